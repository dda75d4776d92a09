//! The transposed convolution whose kernel equals its stride `k` (no
//! overlap, no padding: the U-Net's 2x2 upsampling), NCHW f32, forward and
//! gradients on tiles of input rows, each tile's product read from and
//! written to the NCHW tensors in place.
//!
//! Every input pixel feeds its own `k x k` block of output pixels, so for a
//! tile of input rows the output is the product `Z = Wᵀ · X_tile` (`[co·k·k,
//! tile pixels]`, row `(c, dy, dx)`) shuffled into the tile's output rows.
//! The gradients are the same product read backwards: with `S` the tile's
//! output gradient shuffled into that layout, the input's is `W · S` and the
//! weight's `Σ_tiles X_tile · Sᵀ`.
//!
//! Why: the path before this one copied the whole input to a channel-major
//! layout, made one product through burn's matmul into a `[co·k·k, n·h·w]`
//! buffer as large as the output, and shuffled that into the output: four
//! passes over memory around a product of a few MFLOP (the four 2x2
//! upsamplings of the width-16 U-Net: 4.3 ms of its 84 ms forward at one
//! thread, BENCHMARKS.md). Here a tile's `Z` or `S` is built and consumed
//! while it is in cache, and nothing else is copied: 3.0 ms.

// The products read and write the NCHW tensors through the `gemm` crate's
// pointer interface; every extent is checked against the slices' lengths
// before the unsafe blocks.
#![allow(unsafe_code)]

use crate::conv_backward::{add_partials, GROUPS};
use crate::conv_forward::{inner_parallelism, tile_rows, Out};
use crate::product::{product, row_major, transposed};
use rayon::prelude::*;

/// Shape of a non-overlapping transposed convolution: `n` images of `ci`
/// planes of `h` x `w` to `co` planes of `h·k` x `w·k`, weight `(ci, co, k,
/// k)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct UpGeom {
    /// Images in the batch.
    pub n: usize,
    /// Input channels.
    pub ci: usize,
    /// Output channels.
    pub co: usize,
    /// Input height.
    pub h: usize,
    /// Input width.
    pub w: usize,
    /// Kernel side and stride.
    pub k: usize,
}

impl UpGeom {
    /// Rows of a tile's shuffled block: `co·k·k`.
    fn rows(&self) -> usize {
        self.co * self.k * self.k
    }

    /// Input rows per tile (at least one, at most `h`): cache-sized blocks
    /// of `Z` or `S`, as the convolutions' tiles.
    fn tile_rows(&self) -> usize {
        tile_rows(self.rows(), self.w).min(self.h.max(1))
    }

    /// The tiles: `(image, first input row, rows)`, image by image.
    fn tiles(&self) -> Vec<(usize, usize, usize)> {
        let rows = self.tile_rows();
        (0..self.n)
            .flat_map(|img| (0..self.h).step_by(rows).map(move |r0| (img, r0, rows)))
            .map(|(img, r0, rows)| (img, r0, rows.min(self.h - r0)))
            .collect()
    }

    fn check(&self, x: usize, weight: usize, out: usize) {
        let (hw, kk) = (self.h * self.w, self.k * self.k);
        assert!(self.k > 0, "kernel side");
        assert_eq!(x, self.n * self.ci * hw, "input size");
        assert_eq!(weight, self.ci * self.co * kk, "weight size");
        assert_eq!(out, self.n * self.co * hw * kk, "output size");
    }
}

/// `out = conv_transpose(x, weight) + bias`: `x` is `(n, ci, h, w)`,
/// `weight` `(ci, co, k, k)`, `bias` `co` values, `out` `(n, co, h·k, w·k)`,
/// every element written. Parallel over tiles of input rows.
pub fn upconv_forward(
    x: &[f32],
    g: &UpGeom,
    weight: &[f32],
    bias: Option<&[f32]>,
    out: &mut [f32],
) {
    g.check(x.len(), weight.len(), out.len());
    if let Some(b) = bias {
        assert_eq!(b.len(), g.co, "bias size");
    }
    if out.is_empty() {
        return;
    }
    let (rows, hw) = (g.rows(), g.h * g.w);
    let tiles = g.tiles();
    let par = inner_parallelism(tiles.len());
    let dst = Out(out.as_mut_ptr());
    tiles
        .par_iter()
        .for_each_init(Vec::new, |z, &(img, r0, nr)| {
            let len = nr * g.w;
            z.resize(rows * len, 0.0);
            let src = img * g.ci * hw + r0 * g.w;
            // `X_tile` element (c, l) is `x[src + c * hw + l]`, the last below
            // `(img + 1) * ci * hw`; `Wᵀ` element (r, c) is `weight[c * rows + r]`.
            assert!(src + (g.ci - 1) * hw + len <= x.len());
            // SAFETY: the three matrices lie inside `z` (rows x len), `weight`
            // and `x` as checked above; `z` is this task's own buffer.
            unsafe {
                product(
                    (rows, len, g.ci),
                    row_major(z.as_mut_ptr(), len),
                    false,
                    transposed(weight.as_ptr(), rows),
                    row_major(x.as_ptr().add(src), hw),
                    par,
                );
            }
            let (k, ow) = (g.k, g.w * g.k);
            for c in 0..g.co {
                let b = bias.map_or(0.0, |b| b[c]);
                // Output rows k·r0 .. k·(r0 + nr) of plane (img, c): this
                // tile's only, so no other task writes them.
                let at = (img * g.co + c) * hw * k * k + r0 * k * ow;
                // SAFETY: `at + nr * k * ow <= out.len()` (the plane holds h·k
                // rows of ow and r0 + nr <= h), and the rows are this tile's.
                let block = unsafe { std::slice::from_raw_parts_mut(dst.at(at), nr * k * ow) };
                for y in 0..nr {
                    for dy in 0..k {
                        let line = &mut block[(y * k + dy) * ow..][..ow];
                        let zr = |dx: usize| &z[((c * k + dy) * k + dx) * len + y * g.w..][..g.w];
                        scatter_line(line, k, b, zr);
                    }
                }
            }
        });
}

/// One output row from the `k` rows of `Z` it interleaves (`zr(dx)`), plus
/// `b`; the 2x2 case written out so that it vectorises.
#[inline(always)]
fn scatter_line<'z>(line: &mut [f32], k: usize, b: f32, zr: impl Fn(usize) -> &'z [f32]) {
    if k == 2 {
        let (z0, z1) = (zr(0), zr(1));
        for ((pair, &a), &c) in line.chunks_exact_mut(2).zip(z0).zip(z1) {
            pair[0] = a + b;
            pair[1] = c + b;
        }
    } else {
        for dx in 0..k {
            for (o, &v) in line.iter_mut().skip(dx).step_by(k).zip(zr(dx)) {
                *o = v + b;
            }
        }
    }
}

/// The tile's output gradient in `Z`'s layout: `s` (`co·k·k` rows of `nr·w`)
/// from rows `k·r0 ..` of image `img`'s planes of `dy`.
fn gather_tile(dy: &[f32], g: &UpGeom, (img, r0, nr): (usize, usize, usize), s: &mut Vec<f32>) {
    let (k, ow, len) = (g.k, g.w * g.k, nr * g.w);
    let plane = g.h * g.w * k * k;
    s.resize(g.rows() * len, 0.0);
    for c in 0..g.co {
        let src = &dy[(img * g.co + c) * plane + r0 * k * ow..][..nr * k * ow];
        for dy_ in 0..k {
            for dx in 0..k {
                let row = &mut s[((c * k + dy_) * k + dx) * len..][..len];
                for y in 0..nr {
                    let line = &src[(y * k + dy_) * ow..][..ow];
                    let dst = &mut row[y * g.w..][..g.w];
                    for (o, &v) in dst.iter_mut().zip(line.iter().skip(dx).step_by(k)) {
                        *o = v;
                    }
                }
            }
        }
    }
}

/// Gradients of [`upconv_forward`] from the output gradient `dy` `(n, co,
/// h·k, w·k)`: `dx` `(n, ci, h, w)` and `dw` `(ci, co, k, k)` (each
/// overwritten when given). One pass over the tiles, in a fixed number of
/// groups summed in order: the weight gradient has the same bits whatever
/// the thread count. The bias gradient is [`crate::conv::channel_sums`] of
/// `dy`.
pub fn upconv_backward(
    x: &[f32],
    g: &UpGeom,
    weight: &[f32],
    dy: &[f32],
    dx: Option<&mut [f32]>,
    dw: Option<&mut [f32]>,
) {
    g.check(x.len(), weight.len(), dy.len());
    if dx.is_none() && dw.is_none() {
        return;
    }
    let rows = g.rows();
    let tiles = g.tiles();
    let groups = tiles.len().min(GROUPS);
    let par = inner_parallelism(groups);
    let dx = dx.map(|d| {
        assert_eq!(d.len(), x.len(), "input gradient size");
        Out(d.as_mut_ptr())
    });
    let want_dw = dw.is_some();
    let partials: Vec<Vec<f32>> = (0..groups)
        .into_par_iter()
        .map(|grp| {
            let mut part = vec![0.0f32; if want_dw { g.ci * rows } else { 0 }];
            let mut s = Vec::new();
            for &tile in &tiles[grp * tiles.len() / groups..(grp + 1) * tiles.len() / groups] {
                gather_tile(dy, g, tile, &mut s);
                let (img, r0, nr) = tile;
                let at = img * g.ci * g.h * g.w + r0 * g.w;
                if let Some(d) = dx {
                    // SAFETY: rows r0..r0+nr of image img's input planes are
                    // this tile's only and lie inside `dx` (its length is
                    // x's, checked above).
                    unsafe { tile_input_grad(g, weight, &s, nr * g.w, d.at(at), par) };
                }
                if want_dw {
                    tile_weight_grad(g, &x[at..], &s, nr * g.w, &mut part, par);
                }
            }
            part
        })
        .collect();
    if let Some(dw) = dw {
        assert_eq!(dw.len(), g.ci * rows, "weight gradient size");
        dw.fill(0.0);
        add_partials(&partials, dw);
    }
}

/// `dX_tile = W · S` written into the input gradient's rows at `d`
/// (`ci` rows of `len`, `h·w` apart).
///
/// # Safety
/// `d` must point at `ci` rows of `len` writable values `h·w` apart that no
/// other thread touches.
unsafe fn tile_input_grad(
    g: &UpGeom,
    weight: &[f32],
    s: &[f32],
    len: usize,
    d: *mut f32,
    par: gemm::Parallelism,
) {
    let rows = g.rows();
    assert!(s.len() >= rows * len && weight.len() == g.ci * rows);
    // SAFETY: the caller's contract for `d`; `W` (ci x rows) and `S` (rows
    // x len) lie inside `weight` and `s` as checked above.
    unsafe {
        product(
            (g.ci, len, rows),
            row_major(d, g.h * g.w),
            false,
            row_major(weight.as_ptr(), rows),
            row_major(s.as_ptr(), len),
            par,
        );
    }
}

/// `part += X_tile · Sᵀ`: `x` from the tile's first pixel (`ci` rows of
/// `len`, `h·w` apart), `part` `ci x co·k·k`.
fn tile_weight_grad(
    g: &UpGeom,
    x: &[f32],
    s: &[f32],
    len: usize,
    part: &mut [f32],
    par: gemm::Parallelism,
) {
    let (rows, hw) = (g.rows(), g.h * g.w);
    assert!(x.len() >= (g.ci - 1) * hw + len, "tile of the input");
    assert!(s.len() >= rows * len && part.len() == g.ci * rows);
    // SAFETY: `X_tile` (ci x len, row stride hw), `Sᵀ` (len x rows: element
    // (l, r) at s[r * len + l]) and `part` (ci x rows) lie inside the slices
    // as checked above; `part` is the caller's own buffer.
    unsafe {
        product(
            (g.ci, rows, len),
            row_major(part.as_mut_ptr(), rows),
            true,
            row_major(x.as_ptr(), hw),
            transposed(s.as_ptr(), len),
            par,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::conv::tests::values;

    /// The transposed convolution by its definition, f64: out, dx, dw for
    /// the output gradient `dy`.
    fn reference(x: &[f32], g: &UpGeom, wt: &[f32], dy: &[f32]) -> [Vec<f64>; 3] {
        let (k, oh, ow) = (g.k, g.h * g.k, g.w * g.k);
        let mut out = vec![0.0f64; g.n * g.co * oh * ow];
        let mut dx = vec![0.0f64; x.len()];
        let mut dw = vec![0.0f64; wt.len()];
        for j in 0..g.n {
            for c in 0..g.ci {
                for o in 0..g.co {
                    for y in 0..g.h {
                        for xx in 0..g.w {
                            let xi = ((j * g.ci + c) * g.h + y) * g.w + xx;
                            for a in 0..k {
                                for b in 0..k {
                                    let wi = ((c * g.co + o) * k + a) * k + b;
                                    let oi = ((j * g.co + o) * oh + y * k + a) * ow + xx * k + b;
                                    out[oi] += x[xi] as f64 * wt[wi] as f64;
                                    dx[xi] += wt[wi] as f64 * dy[oi] as f64;
                                    dw[wi] += x[xi] as f64 * dy[oi] as f64;
                                }
                            }
                        }
                    }
                }
            }
        }
        [out, dx, dw]
    }

    fn close(name: &str, got: &[f32], want: &[f64], tol: f64) {
        assert_eq!(got.len(), want.len(), "{name} size");
        for (i, (&a, &b)) in got.iter().zip(want).enumerate() {
            assert!(
                (a as f64 - b).abs() <= tol * (1.0 + b.abs()),
                "{name}[{i}]: {a} vs {b}"
            );
        }
    }

    /// Forward and both gradients against the definition: kernels 1 to 3,
    /// odd sides, and frames tall and wide enough to split into many tiles.
    #[test]
    fn matches_the_definition() {
        let cases = [
            (2, 6, 3, 5, 4, 2),
            (1, 4, 4, 1, 3, 2),
            (3, 3, 2, 4, 5, 3),
            (2, 2, 3, 3, 3, 1),
            (2, 8, 16, 70, 9, 2),
            (1, 32, 16, 9, 300, 2),
        ];
        for (case, &(n, ci, co, h, w, k)) in cases.iter().enumerate() {
            let g = UpGeom { n, ci, co, h, w, k };
            let x = values(n * ci * h * w, 3 + case as u64);
            let wt = values(ci * co * k * k, 11 + case as u64);
            let bias = values(co, 17 + case as u64);
            let dy = values(n * co * h * w * k * k, 23 + case as u64);
            let [out, dx, dw] = reference(&x, &g, &wt, &dy);
            let mut got = vec![f32::NAN; out.len()];
            upconv_forward(&x, &g, &wt, Some(&bias), &mut got);
            let plane = h * w * k * k;
            let with_bias: Vec<f64> = out
                .iter()
                .enumerate()
                .map(|(i, &v)| v + bias[(i / plane) % co] as f64)
                .collect();
            close(&format!("case {case} forward"), &got, &with_bias, 1e-5);
            let (mut gx, mut gw) = (vec![f32::NAN; dx.len()], vec![f32::NAN; dw.len()]);
            upconv_backward(&x, &g, &wt, &dy, Some(&mut gx), Some(&mut gw));
            close(&format!("case {case} input gradient"), &gx, &dx, 1e-5);
            close(&format!("case {case} weight gradient"), &gw, &dw, 1e-4);
            if case == 5 {
                assert!(g.tile_rows() < h, "case {case} spans tiles");
            }
        }
    }

    /// The weight gradient has the same bits on one thread and on four, and
    /// either gradient may be asked for alone.
    #[test]
    fn weight_gradient_does_not_depend_on_the_threads() {
        let g = UpGeom {
            n: 3,
            ci: 16,
            co: 32,
            h: 40,
            w: 300,
            k: 2,
        };
        let x = values(g.n * g.ci * g.h * g.w, 5);
        let wt = values(g.ci * g.co * 4, 6);
        let dy = values(g.n * g.co * g.h * g.w * 4, 7);
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let mut dw = vec![0.0; wt.len()];
                upconv_backward(&x, &g, &wt, &dy, None, Some(&mut dw));
                let mut dx = vec![0.0; x.len()];
                upconv_backward(&x, &g, &wt, &dy, Some(&mut dx), None);
                (dw, dx)
            })
        };
        let (one, four) = (run(1), run(4));
        assert!(one.0 == four.0, "weight gradient bits");
        assert!(one.1 == four.1, "input gradient bits");
        assert!(g.tiles().len() > GROUPS, "more tiles than groups");
    }
}
