//! The loops under pgrf's own training operations (`pgrf_nn::ops`), on plain
//! `f32` slices in NCHW order, free of the deep-learning framework so that
//! they are tested against naive references here and compiled with full
//! optimisation even in the dev profile.
//!
//! Why they exist: burn 0.21's Flex backend computes a convolution's weight
//! gradient as a forward convolution over strided `swap_dims` views, copies
//! the whole output gradient for the bias gradient, scatters the input
//! gradient serially (col2im), and decomposes activations and Adam into
//! many full-size passes (BENCHMARKS.md, "Training step"). The
//! convolutions here call the `gemm` crate (the one Flex multiplies with)
//! on tiles of output rows that stay in cache, forward and backward; the
//! rest is the data movement around products, done once, contiguously and
//! in parallel.
//!
//! - [`conv`]: convolution geometry, im2col and its adjoint col2im, the
//!   `[channels, n * pixels]` layout the products run on and per-channel
//!   sums (bias gradients).
//! - [`conv_forward`]: the forward convolution over cache-sized tiles of
//!   output rows, one `gemm` product each, bias written first.
//! - [`conv_backward`]: the weight gradient summed over the same tiles in a
//!   fixed order, and a stride-1 input gradient as a forward convolution.
//! - [`act`]: LeakyReLU and SiLU forward and backward, SiLU with a
//!   branch-free exp the compiler vectorises.
//! - [`norm`]: GroupNorm with its affine, forward and backward, per
//!   (image, group) block.
//! - [`upconv`]: the non-overlapping transposed convolution (the U-Net's
//!   2x2 upsampling), forward and gradients, on tiles of input rows.
//! - [`adam`]: one pass per parameter tensor for Adam's update.

pub mod act;
pub mod adam;
pub mod conv;
pub mod conv_backward;
pub mod conv_forward;
pub mod norm;
mod product;
pub mod upconv;

/// Elements per rayon task in the element-wise kernels: large enough that
/// task overhead is negligible, small enough that two threads share a
/// 100 k-element tensor.
pub(crate) const CHUNK: usize = 1 << 14;

/// A zeroed buffer of `len` values, zeroed in parallel: a fresh buffer from
/// a recycled allocation must be cleared, and one thread clearing tens of MB
/// between parallel kernels was 4 % of a 2-thread training step (the
/// kernels overwrite every value, but safe Rust has no uninitialised
/// buffer to hand them).
pub fn zeroed(len: usize) -> Vec<f32> {
    use rayon::prelude::*;
    let mut v = Vec::with_capacity(len);
    v.par_extend(rayon::iter::repeat_n(0.0f32, len).with_min_len(CHUNK));
    v
}

#[cfg(test)]
mod tests {
    #[test]
    fn zeroed_is_zero_and_of_the_length() {
        for len in [0, 1, super::CHUNK + 3, 5 * super::CHUNK] {
            let v = super::zeroed(len);
            assert_eq!(v.len(), len);
            assert!(v.iter().all(|&x| x == 0.0));
        }
    }
}
