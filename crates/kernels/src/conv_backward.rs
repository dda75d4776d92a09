//! The 2-D convolution's weight and input gradients, NCHW f32, on the same
//! row tiles as the forward ([`crate::conv_forward`]).
//!
//! Why: issue 15's backward built the im2col of a whole chunk of images
//! (37 MB at the U-Net's first level), copied the output gradient into a
//! channel-major layout, and handed one product with a 32 768-long inner
//! dimension to gemm, which splits only the outer ones across threads: the
//! 3x3 convolutions' backward was 245 ms of a 380 ms U-Net step at 2
//! threads, 3.5 times their forward (BENCHMARKS.md, issue 38).
//!
//! - The weight gradient `dW = Σ_tiles dY_tile · col_tileᵀ` is summed over
//!   tiles of output rows whose im2col block stays in cache. `dY_tile` is
//!   read in place (rows `r0..r1` of every output plane are a matrix with
//!   row stride `oh * ow`), so no layout copy is made. The tiles are split
//!   into a fixed number of groups, each summed by one task into its own
//!   partial, and the partials are added in group order: the result is the
//!   same bits whatever the thread count.
//! - The input gradient of a stride-1 convolution is itself a forward
//!   convolution: of `dY` by the kernel flipped in both axes with its two
//!   channel axes swapped, padded by `k - 1 - p`. It runs through the
//!   forward's tiles, with no col2im scatter and no write conflicts.

// The weight gradient's products accumulate into each group's partial
// through the `gemm` crate's pointer interface; every extent is checked
// against the slices' lengths before the unsafe block.
#![allow(unsafe_code)]

use crate::conv::{tile_matrix, ConvGeom};
use crate::conv_forward::{conv2d_forward, inner_parallelism, rows_per_tile};
use crate::product::{product, row_major, transposed};
use rayon::prelude::*;

/// Groups the weight gradient's tiles are split into: enough that 16
/// threads stay busy on the large early layers, few enough that adding the
/// partials (one `co x ci·kh·kw` buffer each) is cheap. A constant, not
/// the thread count, so that the sum's order does not depend on it. The
/// upsampling's weight gradient ([`crate::upconv`]) is summed the same way.
pub(crate) const GROUPS: usize = 16;

/// `dw = ∂L/∂W` of `out = conv(x, W)`: `x` is `(n, ci, h, w)`, `dy` is
/// `(n, co, oh, ow)`, `dw` is `(co, ci, kh, kw)` and is overwritten.
pub fn conv2d_weight_grad(x: &[f32], g: &ConvGeom, dy: &[f32], co: usize, dw: &mut [f32]) {
    let (oh, ow) = g.out_hw().expect("a valid geometry");
    let (k, per) = (g.rows(), oh * ow);
    assert_eq!(x.len(), g.n * g.ci * g.h * g.w, "input size");
    assert_eq!(dy.len(), g.n * co * per, "output gradient size");
    assert_eq!(dw.len(), co * k, "weight gradient size");
    dw.fill(0.0);
    if dy.is_empty() || dw.is_empty() {
        return;
    }
    let rows = rows_per_tile(g, ow).min(oh);
    let tiles_per_image = oh.div_ceil(rows);
    let tasks = g.n * tiles_per_image;
    let groups = tasks.min(GROUPS);
    let inner = inner_parallelism(groups);
    let partials: Vec<Vec<f32>> = (0..groups)
        .into_par_iter()
        .map(|grp| {
            let tiles = grp * tasks / groups..(grp + 1) * tasks / groups;
            let rows = TileRows {
                rows,
                per_image: tiles_per_image,
                oh,
                ow,
            };
            group_weight_grad(x, g, dy, co, tiles, rows, inner)
        })
        .collect();
    add_partials(&partials, dw);
}

/// How [`conv2d_weight_grad`] cuts the output into tiles: `rows` output
/// rows per tile, `per_image` tiles per image, output `oh` x `ow`.
#[derive(Clone, Copy)]
struct TileRows {
    rows: usize,
    per_image: usize,
    oh: usize,
    ow: usize,
}

/// One group's partial weight gradient: `Σ dY_tile · col_tileᵀ` over the
/// tiles `tiles` (numbered image by image), `co x ci·kh·kw`.
fn group_weight_grad(
    x: &[f32],
    g: &ConvGeom,
    dy: &[f32],
    co: usize,
    tiles: std::ops::Range<usize>,
    t: TileRows,
    inner: gemm::Parallelism,
) -> Vec<f32> {
    let (k, per, ow, rows) = (g.rows(), t.oh * t.ow, t.ow, t.rows);
    let mut part = vec![0.0f32; co * k];
    let mut col = Vec::new();
    for i in tiles {
        let (img, r0) = (i / t.per_image, (i % t.per_image) * rows);
        let r1 = (r0 + rows).min(t.oh);
        let len = (r1 - r0) * ow;
        let (m, m_rs) = tile_matrix(x, g, img, r0..r1, &mut col);
        let base = img * co * per + r0 * ow;
        // `dY_tile` element (o, l) is `dy[base + o * per + l]`, the
        // last at `base + (co - 1) * per + len - 1 < (img + 1) * co *
        // per <= dy.len()`; the tile matrix's transpose has element
        // (l, r) at `m[r * m_rs + l]`, inside `m` (k rows of len,
        // stride m_rs); `part` is co x k.
        assert!(base + (co - 1) * per + len <= dy.len());
        assert!(m.len() >= (k - 1) * m_rs + len, "tile matrix extent");
        // SAFETY: the three matrices lie inside `dy`, `m` and `part`
        // as checked above; `part` is this task's own buffer and
        // gemm only reads `dy` and `m`.
        unsafe {
            product(
                (co, k, len),
                row_major(part.as_mut_ptr(), k),
                true,
                row_major(dy.as_ptr().add(base), per),
                transposed(m.as_ptr(), m_rs),
                inner,
            );
        }
    }
    part
}

/// `dw += Σ partials`, the partials added in their order (so the sum has
/// the same bits at any thread count), in parallel over chunks of `dw`.
pub(crate) fn add_partials(partials: &[Vec<f32>], dw: &mut [f32]) {
    dw.par_chunks_mut(crate::CHUNK)
        .enumerate()
        .for_each(|(i, out)| {
            let at = i * crate::CHUNK;
            for part in partials {
                for (o, p) in out.iter_mut().zip(&part[at..]) {
                    *o += p;
                }
            }
        });
}

/// Whether [`conv2d_input_grad`] covers `g`: stride 1 and a padding no
/// larger than the kernel less one on each axis (the forward convolution
/// it becomes needs a non-negative padding).
pub fn input_grad_is_a_forward(g: &ConvGeom) -> bool {
    g.stride == [1, 1] && g.pad[0] < g.kh && g.pad[1] < g.kw && g.out_hw().is_some()
}

/// `dx = ∂L/∂x` of `out = conv(x, W)` for a stride-1 convolution
/// ([`input_grad_is_a_forward`]): `dy` is `(n, co, oh, ow)`, `weight` is
/// `(co, ci, kh, kw)`, `dx` is `(n, ci, h, w)` and is overwritten. The
/// forward convolution of `dy` by `W'[c, o, ky, kx] = W[o, c, kh - 1 - ky,
/// kw - 1 - kx]` padded by `kh - 1 - py`, `kw - 1 - px`.
pub fn conv2d_input_grad(dy: &[f32], g: &ConvGeom, weight: &[f32], co: usize, dx: &mut [f32]) {
    assert!(input_grad_is_a_forward(g), "a stride-1 geometry: {g:?}");
    let (oh, ow) = g.out_hw().expect("checked");
    let taps = g.kh * g.kw;
    assert_eq!(weight.len(), co * g.ci * taps, "weight size");
    // Blocks of BLOCK flipped output channels, in parallel: for each input
    // channel `o` of the flipped kernel the block's BLOCK source kernels are
    // adjacent in `weight`, and the block writes BLOCK sequential streams.
    // Copying one kernel at a time (the 512 x 512 x 3 x 3 one read with an
    // 18 KB stride) took 2 ms, as long as that layer's forward product.
    const BLOCK: usize = 16;
    let mut flipped = vec![0.0f32; weight.len()];
    flipped
        .par_chunks_mut(BLOCK * co * taps)
        .enumerate()
        .for_each(|(b, block)| {
            let c0 = b * BLOCK;
            let rows = block.len() / (co * taps);
            for o in 0..co {
                let src = &weight[(o * g.ci + c0) * taps..][..rows * taps];
                for (cc, kernel) in src.chunks(taps).enumerate() {
                    let dst = &mut block[(cc * co + o) * taps..][..taps];
                    for (d, v) in dst.iter_mut().zip(kernel.iter().rev()) {
                        *d = *v;
                    }
                }
            }
        });
    let back = ConvGeom {
        n: g.n,
        ci: co,
        h: oh,
        w: ow,
        kh: g.kh,
        kw: g.kw,
        stride: [1, 1],
        pad: [g.kh - 1 - g.pad[0], g.kw - 1 - g.pad[1]],
    };
    debug_assert_eq!(back.out_hw(), Some((g.h, g.w)));
    conv2d_forward(dy, &back, &flipped, g.ci, None, None, dx);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::conv::tests::{kernel_cases, values};

    /// Both gradients by their definitions, in f64: `dw[o, c, ky, kx] =
    /// Σ dy[j, o, oy, ox] x[j, c, iy, ix]` and `dx[j, c, iy, ix] = Σ dy[j,
    /// o, oy, ox] w[o, c, ky, kx]` over the taps that land inside.
    fn naive(x: &[f32], g: &ConvGeom, w: &[f32], dy: &[f32], co: usize) -> (Vec<f64>, Vec<f64>) {
        let (oh, ow) = g.out_hw().unwrap();
        let mut dw = vec![0.0f64; w.len()];
        let mut dx = vec![0.0f64; x.len()];
        for j in 0..g.n {
            for o in 0..co {
                for oy in 0..oh {
                    for ox in 0..ow {
                        let d = f64::from(dy[((j * co + o) * oh + oy) * ow + ox]);
                        for c in 0..g.ci {
                            for ky in 0..g.kh {
                                for kx in 0..g.kw {
                                    let iy = (oy * g.stride[0] + ky) as isize - g.pad[0] as isize;
                                    let ix = (ox * g.stride[1] + kx) as isize - g.pad[1] as isize;
                                    if iy < 0 || ix < 0 || iy >= g.h as isize || ix >= g.w as isize
                                    {
                                        continue;
                                    }
                                    let xi =
                                        ((j * g.ci + c) * g.h + iy as usize) * g.w + ix as usize;
                                    let wi = ((o * g.ci + c) * g.kh + ky) * g.kw + kx;
                                    dw[wi] += d * f64::from(x[xi]);
                                    dx[xi] += d * f64::from(w[wi]);
                                }
                            }
                        }
                    }
                }
            }
        }
        (dw, dx)
    }

    fn worst(got: &[f32], want: &[f64]) -> f64 {
        got.iter()
            .zip(want)
            .map(|(a, b)| (f64::from(*a) - b).abs())
            .fold(0.0, f64::max)
    }

    #[test]
    fn gradients_match_their_definitions() {
        for (i, (g, co)) in kernel_cases().into_iter().enumerate() {
            let (n, ci, h, w, k) = (g.n, g.ci, g.h, g.w, g.kh);
            let (s, p) = (g.stride[0], g.pad[0]);
            let (oh, ow) = g.out_hw().unwrap();
            let x = values(n * ci * h * w, 3 * i as u64 + 1);
            let wt = values(co * ci * k * k, 3 * i as u64 + 2);
            let dy = values(n * co * oh * ow, 3 * i as u64 + 3);
            let (want_dw, want_dx) = naive(&x, &g, &wt, &dy, co);
            let mut dw = vec![f32::NAN; wt.len()];
            conv2d_weight_grad(&x, &g, &dy, co, &mut dw);
            // f32 sums of up to 2 x 70 x 66 products of values in [-1, 1]
            // (random signs, so the sums grow like their square root)
            // against f64 ones: within 1e-3 absolute.
            let e = worst(&dw, &want_dw);
            assert!(e < 1e-3, "case {i} {g:?}: weight gradient off by {e}");
            let as_forward = s == 1 && p < k;
            assert_eq!(input_grad_is_a_forward(&g), as_forward, "case {i}");
            if as_forward {
                let mut dx = vec![f32::NAN; x.len()];
                conv2d_input_grad(&dy, &g, &wt, co, &mut dx);
                let e = worst(&dx, &want_dx);
                // At most co x k x k = 72 products per entry: 1e-4.
                assert!(e < 1e-4, "case {i} {g:?}: input gradient off by {e}");
            }
        }
    }

    #[test]
    fn weight_gradient_bits_do_not_depend_on_the_thread_count() {
        // Six tiles (one product per task) and one tile (the product split
        // over the pool).
        for (n, ci, h, w) in [(2, 8, 64, 40), (1, 64, 8, 8)] {
            let g = ConvGeom {
                n,
                ci,
                h,
                w,
                kh: 3,
                kw: 3,
                stride: [1, 1],
                pad: [1, 1],
            };
            let (oh, ow) = g.out_hw().unwrap();
            let x = values(g.n * g.ci * g.h * g.w, 11);
            let dy = values(g.n * 12 * oh * ow, 12);
            let run = |threads: usize| {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let mut dw = vec![0.0f32; 12 * g.rows()];
                pool.install(|| conv2d_weight_grad(&x, &g, &dy, 12, &mut dw));
                dw
            };
            let one = run(1);
            assert_eq!(one, run(2), "{g:?}");
            assert_eq!(one, run(5), "{g:?}");
        }
    }
}
