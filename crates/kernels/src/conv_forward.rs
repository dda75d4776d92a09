//! The forward 2-D convolution, NCHW f32, as im2col over tiles of output
//! rows and one matrix product per tile (the `gemm` crate's, which picks
//! AVX-512, AVX2/FMA or baseline code at run time), the bias written first
//! and the product added to it.
//!
//! Why tiles: an im2col of a whole image is `ci * kh * kw` times its size
//! (19 MB per image at the U-Net's first level), and writing it then
//! reading it back cost more than burn Flex's convolution saved
//! (BENCHMARKS.md, issue 15: 330 ms against Flex's 252 ms for the U-Net's
//! forward). A tile of output rows whose im2col block fits in a core's L2
//! cache is built and consumed while it is still there; tiles are
//! independent, so both cores work from the first layer to the last without
//! the serial layout copies Flex makes around its products.

// The products write each tile's rows straight into the NCHW output through
// the `gemm` crate's pointer interface; every pointer and extent is checked
// against the slices' lengths before the one unsafe block.
#![allow(unsafe_code)]

use crate::conv::{tile_matrix, ConvGeom};
use crate::product::{product, row_major};
use rayon::prelude::*;

/// Bytes of one tile's block (a convolution's im2col, an upsampling's
/// shuffled product): about half a core's L2 cache on the machines pgrf
/// runs on (512 KiB to 2 MiB per core), so the block and the weights' panel
/// stay cached while the product reads them.
const TILE_BYTES: usize = 256 << 10;

/// Pixels a tile has at least, whatever its block's size: the product's
/// columns, below which gemm's packing costs more than it saves.
const MIN_TILE_PIXELS: usize = 256;

/// Rows per tile (at least one) for a block of `block_rows` rows of `width`
/// pixels per image row: as many as [`TILE_BYTES`] holds, and at least
/// [`MIN_TILE_PIXELS`].
pub(crate) fn tile_rows(block_rows: usize, width: usize) -> usize {
    let per_row = block_rows * width * std::mem::size_of::<f32>();
    let by_cache = TILE_BYTES / per_row.max(1);
    let by_width = MIN_TILE_PIXELS.div_ceil(width.max(1));
    by_cache.max(by_width).max(1)
}

/// Output rows per tile for `g` (at least one); shared with the weight
/// gradient's tiles.
pub(crate) fn rows_per_tile(g: &ConvGeom, ow: usize) -> usize {
    tile_rows(g.rows(), ow)
}

/// gemm's parallelism inside one product of a loop of `tasks` products run
/// in parallel: the pool when the tasks are fewer than the threads (small
/// late layers), none otherwise.
pub(crate) fn inner_parallelism(tasks: usize) -> gemm::Parallelism {
    let threads = rayon::current_num_threads();
    if tasks >= threads {
        gemm::Parallelism::None
    } else {
        gemm::Parallelism::Rayon(threads)
    }
}

/// A raw output pointer handed to the tasks, each of which writes only its
/// own (image, rows) block.
#[derive(Clone, Copy)]
pub(crate) struct Out(pub(crate) *mut f32);
// SAFETY: the tasks write disjoint elements (distinct images or distinct
// output rows of one image), and the buffer outlives the parallel loop.
unsafe impl Send for Out {}
unsafe impl Sync for Out {}

impl Out {
    /// The element `offset` places in (a method, so that closures capture
    /// the whole `Out`, which is `Sync`, not its raw pointer field).
    ///
    /// # Safety
    /// `offset` must lie within the buffer.
    pub(crate) unsafe fn at(self, offset: usize) -> *mut f32 {
        // SAFETY: the caller keeps `offset` in bounds.
        unsafe { self.0.add(offset) }
    }
}

/// One tile of [`conv2d_forward`]: its block of the output, `co` rows of
/// `len` values `per` apart from `d`, and its matrix `m` (k rows of `len`,
/// `m_rs` apart).
struct Tile<'a> {
    d: *mut f32,
    per: usize,
    len: usize,
    m: &'a [f32],
    m_rs: usize,
}

/// The tile's block = bias (when given) + weight x matrix, then the
/// LeakyReLU of slope `leaky` (when given) while the block is in cache.
///
/// # Safety
/// `t.d` must point at a block of `co` rows of `t.len` writable values
/// `t.per` apart that no other thread touches, and `t.m` hold `k` rows of
/// `t.len` values `t.m_rs` apart; `weight` is `co x k`.
#[inline]
unsafe fn tile_product(
    t: &Tile,
    weight: &[f32],
    co: usize,
    k: usize,
    bias: Option<&[f32]>,
    leaky: Option<f32>,
    inner: gemm::Parallelism,
) {
    let (d, per, len) = (t.d, t.per, t.len);
    // SAFETY: the caller's contract: every row touched below lies in the
    // tile's block, and gemm reads `weight` and `t.m` in bounds.
    unsafe {
        if let Some(b) = bias {
            for (ch, &v) in b.iter().enumerate() {
                std::slice::from_raw_parts_mut(d.add(ch * per), len).fill(v);
            }
        }
        product(
            (co, len, k),
            row_major(d, per),
            bias.is_some(),
            row_major(weight.as_ptr(), k),
            row_major(t.m.as_ptr(), t.m_rs),
            inner,
        );
        if let Some(slope) = leaky {
            for ch in 0..co {
                let block = std::slice::from_raw_parts_mut(d.add(ch * per), len);
                for v in block {
                    if *v < 0.0 {
                        *v *= slope;
                    }
                }
            }
        }
    }
}

/// `out = conv(x, weight) + bias`, then LeakyReLU with `leaky` as its slope
/// when given: `x` is `(n, ci, h, w)`, `weight` is `(co, ci, kh, kw)` (so
/// `[co, ci * kh * kw]` row-major), `bias` has `co` values, `out` is `(n,
/// co, oh, ow)`; every element of `out` is written. The activation is
/// applied to each tile right after its product, while the tile is still in
/// cache (inference: training keeps the pre-activation for the backward).
/// Parallel over tiles of output rows (all images), each tile's product on
/// one thread; with fewer tiles than threads (small late layers) the
/// product itself runs on the pool.
pub fn conv2d_forward(
    x: &[f32],
    g: &ConvGeom,
    weight: &[f32],
    co: usize,
    bias: Option<&[f32]>,
    leaky: Option<f32>,
    out: &mut [f32],
) {
    let (oh, ow) = g.out_hw().expect("a valid geometry");
    let (k, per) = (g.rows(), oh * ow);
    assert_eq!(x.len(), g.n * g.ci * g.h * g.w, "input size");
    assert_eq!(weight.len(), co * k, "weight size");
    assert_eq!(out.len(), g.n * co * per, "output size");
    if let Some(b) = bias {
        assert_eq!(b.len(), co, "bias size");
    }
    if out.is_empty() {
        return;
    }
    let rows = rows_per_tile(g, ow).min(oh);
    let tiles_per_image = oh.div_ceil(rows);
    let tasks = g.n * tiles_per_image;
    let inner = inner_parallelism(tasks);
    let dst = Out(out.as_mut_ptr());
    (0..tasks)
        .into_par_iter()
        .for_each_init(Vec::new, |col, t| {
            let (img, r0) = (t / tiles_per_image, (t % tiles_per_image) * rows);
            let r1 = (r0 + rows).min(oh);
            let len = (r1 - r0) * ow;
            let (m, m_rs) = tile_matrix(x, g, img, r0..r1, col);
            assert!(m.len() >= (k - 1) * m_rs + len, "tile matrix extent");
            let base = img * co * per + r0 * ow;
            // The tile's block of `out`: rows `r0..r1` of every output plane of
            // image `img`, at `base + ch * per + i` for `i < len`; the last
            // element lies below `out.len()` (checked by the asserts above:
            // `base + (co - 1) * per + len <= (img + 1) * co * per`).
            // SAFETY: the pointers cover `weight` (co x k), the tile's matrix
            // `m` (k rows of len, stride m_rs, checked above) and the tile's
            // block of `out` (co rows of len, stride per), all in
            // bounds as computed above; no other task writes that block, and
            // gemm reads its inputs only.
            unsafe {
                let tile = Tile {
                    d: dst.at(base),
                    per,
                    len,
                    m,
                    m_rs,
                };
                tile_product(&tile, weight, co, k, bias, leaky, inner);
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::conv::tests::{kernel_cases, values};

    /// The definition: a sum over channels and kernel taps, zero padding.
    fn naive(x: &[f32], g: &ConvGeom, w: &[f32], co: usize, b: Option<&[f32]>) -> Vec<f32> {
        let (oh, ow) = g.out_hw().unwrap();
        let mut out = vec![0.0f32; g.n * co * oh * ow];
        for n in 0..g.n {
            for o in 0..co {
                for oy in 0..oh {
                    for ox in 0..ow {
                        let mut s = b.map_or(0.0, |b| b[o] as f64);
                        for c in 0..g.ci {
                            for ky in 0..g.kh {
                                for kx in 0..g.kw {
                                    let iy = (oy * g.stride[0] + ky) as isize - g.pad[0] as isize;
                                    let ix = (ox * g.stride[1] + kx) as isize - g.pad[1] as isize;
                                    if iy < 0 || ix < 0 || iy >= g.h as isize || ix >= g.w as isize
                                    {
                                        continue;
                                    }
                                    let xv =
                                        x[((n * g.ci + c) * g.h + iy as usize) * g.w + ix as usize];
                                    let wv = w[((o * g.ci + c) * g.kh + ky) * g.kw + kx];
                                    s += xv as f64 * wv as f64;
                                }
                            }
                        }
                        out[((n * co + o) * oh + oy) * ow + ox] = s as f32;
                    }
                }
            }
        }
        out
    }

    #[test]
    fn matches_the_definition_over_sizes_strides_and_paddings() {
        for (i, (g, co)) in kernel_cases().into_iter().enumerate() {
            let (n, ci, h, w, k) = (g.n, g.ci, g.h, g.w, g.kh);
            let (oh, ow) = g.out_hw().unwrap();
            let x = values(n * ci * h * w, 2 * i as u64 + 1);
            let wt = values(co * ci * k * k, 2 * i as u64 + 2);
            let b = values(co, 99 + i as u64);
            for bias in [Some(b.as_slice()), None] {
                let mut out = vec![f32::NAN; n * co * oh * ow];
                conv2d_forward(&x, &g, &wt, co, bias, None, &mut out);
                let want = naive(&x, &g, &wt, co, bias);
                let worst = out
                    .iter()
                    .zip(&want)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0f32, f32::max);
                // f32 sums of up to 288 products of values in [-1, 1]
                // against f64 ones: within 1e-4 absolute.
                assert!(worst < 1e-4, "case {i} {g:?}: worst {worst}");
            }
        }
    }

    /// The fused LeakyReLU equals the activation applied afterwards, bit
    /// for bit, on a frame of several tiles.
    #[test]
    fn fused_leaky_relu_equals_the_separate_pass() {
        let g = ConvGeom {
            n: 2,
            ci: 32,
            h: 37,
            w: 70,
            kh: 3,
            kw: 3,
            stride: [1, 1],
            pad: [1, 1],
        };
        let (oh, ow) = g.out_hw().unwrap();
        let x = values(g.n * g.ci * g.h * g.w, 21);
        let wt = values(6 * g.rows(), 22);
        let b = values(6, 23);
        let mut plain = vec![0.0f32; g.n * 6 * oh * ow];
        conv2d_forward(&x, &g, &wt, 6, Some(&b), None, &mut plain);
        let mut fused = vec![f32::NAN; plain.len()];
        conv2d_forward(&x, &g, &wt, 6, Some(&b), Some(0.2), &mut fused);
        let negatives = plain.iter().filter(|v| **v < 0.0).count();
        assert!(negatives > plain.len() / 4, "{negatives} negative outputs");
        let mut want = vec![0.0f32; plain.len()];
        crate::act::leaky_relu(&plain, 0.2, &mut want);
        assert_eq!(fused, want);
    }

    #[test]
    fn one_thread_and_the_pool_give_the_same_bits() {
        let g = ConvGeom {
            n: 2,
            ci: 8,
            h: 40,
            w: 36,
            kh: 3,
            kw: 3,
            stride: [1, 1],
            pad: [1, 1],
        };
        let (oh, ow) = g.out_hw().unwrap();
        let x = values(g.n * g.ci * g.h * g.w, 7);
        let wt = values(16 * g.rows(), 8);
        let b = values(16, 9);
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let mut out = vec![0.0f32; g.n * 16 * oh * ow];
            pool.install(|| conv2d_forward(&x, &g, &wt, 16, Some(&b), None, &mut out));
            out
        };
        assert_eq!(run(1), run(2));
    }
}
