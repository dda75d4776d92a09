//! GroupNorm with its affine, forward and backward, each a few passes over
//! one contiguous `(channels / groups) * pixels` block per (image, group),
//! in parallel over blocks; optionally with its statistics taken per window
//! of the image instead of over the whole of it.
//!
//! burn 0.21 builds GroupNorm (and pgrf's folded form, `pgrf_nn::norm`) from
//! a dozen tensor operations whose backward repeats them; here the forward
//! reads the input twice (mean, then variance about it) and writes once, and
//! the backward reads input and output gradient twice and writes once.
//! Sums run in eight f32 lanes over spans of 1024 values and in f64 across
//! spans; biased variance, epsilon inside the root, as burn.
//!
//! Windows: the flow network normalises each window of its training crop's
//! side on its own (`pgrf_nn::norm::windowed`). Cutting the windows out as
//! batch items and putting them back costs two strided copies per GroupNorm
//! (36 % of a 6 MP restoration's time in burn's strided iterator, issue
//! 55); here the statistics are gathered from each window's row segments in
//! place.
//!
//! Blended windows (`GroupShape::blend`, inference): a window's statistics
//! step at its border, and the flow's restoration stepped with them (a grid
//! 1.14x the median step of its error, issue 51). Blended, a pixel within
//! an eighth of a window of a border ([`BLEND_RAMP`]) is normalised by its
//! window's mean and 1 / std mixed linearly with its neighbour's (half and
//! half on the border, bilinearly near a corner); the rest keep their own
//! window's statistics, as the network saw them in training (blending over
//! whole windows, centre to centre, drew ring speckles: MODELS.md), an
//! image of one window is normalised as before, and nothing steps.

use crate::act::silu_of;
use rayon::prelude::*;

/// Layout of a GroupNorm input: `n` images of `c` channels of `height` x
/// `width` values, `groups` groups of `c / groups` consecutive channels,
/// statistics per `window` (rows, columns) tile of each image (the whole
/// image: `(height, width)`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GroupShape {
    /// Images.
    pub n: usize,
    /// Channels (a multiple of `groups`).
    pub c: usize,
    /// Rows per channel.
    pub height: usize,
    /// Columns per channel.
    pub width: usize,
    /// Groups.
    pub groups: usize,
    /// Rows and columns of the windows the statistics are taken over; each
    /// divides its side.
    pub window: (usize, usize),
    /// Statistics blended across window borders ([`blend_weights`]),
    /// forward only: [`group_norm_backward`] refuses more than one blended
    /// window (training normalises each window on its own).
    pub blend: bool,
    /// SiLU applied to the forward's output in the same pass (a flow
    /// network's every GroupNorm is followed by one): one read and one
    /// write of the activation fewer. Forward only: the backward of the
    /// pair is SiLU's then GroupNorm's, taken apart by the caller.
    pub silu: bool,
}

impl GroupShape {
    fn pixels(&self) -> usize {
        self.height * self.width
    }

    fn block(&self) -> usize {
        self.c / self.groups * self.pixels()
    }

    /// Values in one window of one (image, group) block.
    fn window_values(&self) -> usize {
        self.c / self.groups * self.window.0 * self.window.1
    }

    /// Windows per column and per row.
    fn grid(&self) -> (usize, usize) {
        (self.height / self.window.0, self.width / self.window.1)
    }

    fn check(&self, len: usize) {
        assert!(
            self.groups > 0 && self.c.is_multiple_of(self.groups),
            "groups must divide channels"
        );
        let (wy, wx) = self.window;
        assert!(
            wy > 0 && wx > 0 && self.height.is_multiple_of(wy) && self.width.is_multiple_of(wx),
            "windows must tile the image"
        );
        assert_eq!(len, self.n * self.c * self.pixels(), "tensor size");
    }

    /// The row segments of window `(wy, wx)` in one channel of `pixels`
    /// values, as index ranges.
    fn segments(&self, wy: usize, wx: usize) -> impl Iterator<Item = std::ops::Range<usize>> {
        let (sy, sx) = self.window;
        let width = self.width;
        (wy * sy..(wy + 1) * sy).map(move |y| {
            let start = y * width + wx * sx;
            start..start + sx
        })
    }
}

/// Lanes of the partial sums: independent accumulators the compiler keeps
/// in vector registers, so a sum is not one long chain of dependent adds.
const LANES: usize = 8;
/// Elements summed in f32 lanes before the partial sums move to f64.
const SPAN: usize = 1024;

/// `sum f(v)` over `xs`: f32 lanes within spans of [`SPAN`] elements, f64
/// across spans (accurate to ~1e-7 relative for any length).
#[inline(always)]
fn sum_by(xs: &[f32], f: impl Fn(f32) -> f32) -> f64 {
    xs.chunks(SPAN)
        .map(|span| {
            let mut acc = [0.0f32; LANES];
            let mut lanes = span.chunks_exact(LANES);
            for c in &mut lanes {
                for (a, &v) in acc.iter_mut().zip(c) {
                    *a += f(v);
                }
            }
            let tail: f32 = lanes.remainder().iter().map(|&v| f(v)).sum();
            f64::from(acc.iter().sum::<f32>() + tail)
        })
        .sum()
}

/// `(sum dy, sum dy * (x - mean) * rstd)` over one channel, as [`sum_by`].
#[inline(always)]
fn sums_dy(x: &[f32], dy: &[f32], mean: f32, rstd: f32) -> (f64, f64) {
    let (mut total_a, mut total_b) = (0.0f64, 0.0f64);
    for (xs, ds) in x.chunks(SPAN).zip(dy.chunks(SPAN)) {
        let (mut a, mut b) = ([0.0f32; LANES], [0.0f32; LANES]);
        let (mut xl, mut dl) = (xs.chunks_exact(LANES), ds.chunks_exact(LANES));
        for (xc, dc) in (&mut xl).zip(&mut dl) {
            for k in 0..LANES {
                a[k] += dc[k];
                b[k] += dc[k] * ((xc[k] - mean) * rstd);
            }
        }
        let (mut ta, mut tb) = (0.0f32, 0.0f32);
        for (&v, &d) in xl.remainder().iter().zip(dl.remainder()) {
            ta += d;
            tb += d * ((v - mean) * rstd);
        }
        total_a += f64::from(a.iter().sum::<f32>() + ta);
        total_b += f64::from(b.iter().sum::<f32>() + tb);
    }
    (total_a, total_b)
}

/// `sum f(v)` over window `(wy, wx)` of every channel of one block.
#[inline(always)]
fn window_sum(
    block: &[f32],
    s: &GroupShape,
    (wy, wx): (usize, usize),
    f: impl Fn(f32) -> f32 + Copy,
) -> f64 {
    block
        .chunks(s.pixels())
        .map(|ch| s.segments(wy, wx).map(|r| sum_by(&ch[r], f)).sum::<f64>())
        .sum()
}

/// Mean and 1 / sqrt(variance + eps) of window `(wy, wx)` of one block
/// (two passes: the mean, then squared deviations from it).
fn window_stats(block: &[f32], s: &GroupShape, wy: usize, wx: usize, eps: f64) -> (f32, f32) {
    let len = s.window_values().max(1) as f64;
    let mean = (window_sum(block, s, (wy, wx), |v| v) / len) as f32;
    let var = window_sum(block, s, (wy, wx), |v| (v - mean) * (v - mean)) / len;
    (mean, (1.0 / (var + eps).sqrt()) as f32)
}

/// `out = (x - mean) / sqrt(var + eps) * gamma[c] + beta[c]`, statistics per
/// (image, group, window).
pub fn group_norm(
    x: &[f32],
    s: &GroupShape,
    eps: f64,
    gamma: &[f32],
    beta: &[f32],
    out: &mut [f32],
) {
    s.check(x.len());
    assert_eq!(out.len(), x.len(), "output size");
    assert!(gamma.len() == s.c && beta.len() == s.c, "affine sizes");
    let (block, cg, pixels) = (s.block(), s.c / s.groups, s.pixels());
    let (gy, gx) = s.grid();
    if s.blend && (gy, gx) != (1, 1) {
        return blended(x, s, eps, gamma, beta, out);
    }
    out.par_chunks_mut(block.max(1))
        .zip(x.par_chunks(block.max(1)))
        .enumerate()
        .for_each(|(b, (o, x))| {
            let g = b % s.groups;
            for wy in 0..gy {
                for wx in 0..gx {
                    let (mean, rstd) = window_stats(x, s, wy, wx, eps);
                    for k in 0..cg {
                        let ch = g * cg + k;
                        let scale = rstd * gamma[ch];
                        let shift = beta[ch] - mean * scale;
                        let (o, x) = (&mut o[k * pixels..], &x[k * pixels..]);
                        for r in s.segments(wy, wx) {
                            let (o, x) = (&mut o[r.clone()], &x[r]);
                            if s.silu {
                                for (o, &v) in o.iter_mut().zip(x) {
                                    *o = silu_of(v * scale + shift);
                                }
                            } else {
                                for (o, &v) in o.iter_mut().zip(x) {
                                    *o = v * scale + shift;
                                }
                            }
                        }
                    }
                }
            }
        });
}

/// Half-width of the blend across a window border, as a fraction of the
/// window's side: pixels further than this from every border keep their own
/// window's statistics, those nearer are blended linearly with the
/// neighbour's, half and half on the border.
pub const BLEND_RAMP: f64 = 0.125;

/// For each of `len` pixels along an axis cut into `windows` windows of
/// `side`: `(first, second, weight)`, the two windows whose statistics it
/// mixes and the second one's weight ([`BLEND_RAMP`]; both its own window
/// away from the borders and beyond the outermost ones). `pgrf_nn::norm`
/// builds its interpolation matrices from the same weights.
pub fn blend_weights(len: usize, side: usize, windows: usize) -> Vec<(usize, usize, f32)> {
    let last = windows.saturating_sub(1);
    (0..len)
        .map(|i| {
            let u = (i as f64 + 0.5) / side as f64;
            let j = (u.floor() as usize).min(last);
            let frac = u - j as f64;
            if frac < BLEND_RAMP && j > 0 {
                (j - 1, j, (0.5 + frac / (2.0 * BLEND_RAMP)) as f32)
            } else if frac > 1.0 - BLEND_RAMP && j < last {
                (
                    j,
                    j + 1,
                    ((frac - (1.0 - BLEND_RAMP)) / (2.0 * BLEND_RAMP)) as f32,
                )
            } else {
                (j, j, 0.0)
            }
        })
        .collect()
}

/// [`group_norm`] with blended windows: per block, the windows' statistics;
/// then row by row each pixel's blended 1 / std `r` and mean times it `mr`
/// (rows first, then along the row), and every channel's row as
/// `(v r - mr) gamma + beta`: two row-long buffers, one pass per channel.
fn blended(x: &[f32], s: &GroupShape, eps: f64, gamma: &[f32], beta: &[f32], out: &mut [f32]) {
    let (block, cg, pixels, w) = (s.block(), s.c / s.groups, s.pixels(), s.width);
    let (gy, gx) = s.grid();
    let rows = blend_weights(s.height, s.window.0, gy);
    let cols = blend_weights(w, s.window.1, gx);
    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
    out.par_chunks_mut(block.max(1))
        .zip(x.par_chunks(block.max(1)))
        .enumerate()
        .for_each(|(b, (o, x))| {
            let g = b % s.groups;
            let stats: Vec<(f32, f32)> = (0..gy * gx)
                .map(|i| window_stats(x, s, i / gx, i % gx, eps))
                .collect();
            let (mut line, mut r_row, mut mr_row) =
                (vec![(0.0f32, 0.0f32); gx], vec![0.0f32; w], vec![0.0f32; w]);
            for (y, &(j0, j1, ty)) in rows.iter().enumerate() {
                for (i, l) in line.iter_mut().enumerate() {
                    let (a, c) = (stats[j0 * gx + i], stats[j1 * gx + i]);
                    *l = (lerp(a.0, c.0, ty), lerp(a.1, c.1, ty));
                }
                for ((r, mr), &(i0, i1, tx)) in r_row.iter_mut().zip(&mut mr_row).zip(&cols) {
                    let (a, c) = (line[i0], line[i1]);
                    *r = lerp(a.1, c.1, tx);
                    *mr = lerp(a.0, c.0, tx) * *r;
                }
                for k in 0..cg {
                    let ch = g * cg + k;
                    let (gm, bt) = (gamma[ch], beta[ch]);
                    let at = k * pixels + y * w;
                    let (o, x) = (&mut o[at..at + w], &x[at..at + w]);
                    let normed = o.iter_mut().zip(x).zip(r_row.iter().zip(&mr_row));
                    if s.silu {
                        normed
                            .for_each(|((o, &v), (&r, &mr))| *o = silu_of((v * r - mr) * gm + bt));
                    } else {
                        normed.for_each(|((o, &v), (&r, &mr))| *o = (v * r - mr) * gm + bt);
                    }
                }
            }
        });
}

/// Gradients of [`group_norm`] from its input `x` and output gradient `dy`:
/// writes `dx` and returns `(dgamma, dbeta)`, each `c` long. With `xh` the
/// normalised input and `dxh = dy * gamma[c]`, per window of a block: `dx =
/// rstd * (dxh - mean(dxh) - xh * mean(dxh * xh))`.
pub fn group_norm_backward(
    x: &[f32],
    dy: &[f32],
    s: &GroupShape,
    eps: f64,
    gamma: &[f32],
    dx: &mut [f32],
) -> (Vec<f32>, Vec<f32>) {
    s.check(x.len());
    assert!(
        !s.silu,
        "the backward of GroupNorm then SiLU is taken apart"
    );
    assert!(
        !s.blend || s.grid() == (1, 1),
        "blended windows are forward only"
    );
    assert!(dy.len() == x.len() && dx.len() == x.len(), "gradient sizes");
    assert_eq!(gamma.len(), s.c, "affine size");
    let (block, cg) = (s.block(), s.c / s.groups);
    let (gy, gx) = s.grid();
    // Per (image, channel) sums of dy and dy * xh, for the affine's gradients.
    let partial: Vec<(Vec<f64>, Vec<f64>)> = dx
        .par_chunks_mut(block.max(1))
        .zip(x.par_chunks(block.max(1)).zip(dy.par_chunks(block.max(1))))
        .enumerate()
        .map(|(b, (dx, (x, dy)))| {
            let g = b % s.groups;
            let mut sums = (vec![0.0f64; cg], vec![0.0f64; cg]);
            for wy in 0..gy {
                for wx in 0..gx {
                    window_backward(x, dy, dx, s, (wy, wx), eps, &gamma[g * cg..], &mut sums);
                }
            }
            sums
        })
        .collect();
    let (mut dgamma, mut dbeta) = (vec![0.0f64; s.c], vec![0.0f64; s.c]);
    for (b, (sum_dy, sum_dy_xh)) in partial.iter().enumerate() {
        let g = b % s.groups;
        for k in 0..cg {
            dbeta[g * cg + k] += sum_dy[k];
            dgamma[g * cg + k] += sum_dy_xh[k];
        }
    }
    let to32 = |v: Vec<f64>| v.into_iter().map(|v| v as f32).collect();
    (to32(dgamma), to32(dbeta))
}

/// [`group_norm_backward`] on one window of one block: writes the window's
/// `dx` and adds its per-channel sums of `dy` and `dy * xh` to `sums`.
/// `gamma` starts at the block's first channel.
#[allow(clippy::too_many_arguments)]
fn window_backward(
    x: &[f32],
    dy: &[f32],
    dx: &mut [f32],
    s: &GroupShape,
    (wy, wx): (usize, usize),
    eps: f64,
    gamma: &[f32],
    (sum_dy, sum_dy_xh): &mut (Vec<f64>, Vec<f64>),
) {
    let (cg, pixels) = (s.c / s.groups, s.pixels());
    let (mean, rstd) = window_stats(x, s, wy, wx, eps);
    let (mut sum_dxh, mut sum_dxh_xh) = (0.0f64, 0.0f64);
    for k in 0..cg {
        let gm = f64::from(gamma[k]);
        let (xc, dc) = (&x[k * pixels..], &dy[k * pixels..]);
        for r in s.segments(wy, wx) {
            let (a, b2) = sums_dy(&xc[r.clone()], &dc[r], mean, rstd);
            sum_dy[k] += a;
            sum_dy_xh[k] += b2;
            sum_dxh += a * gm;
            sum_dxh_xh += b2 * gm;
        }
    }
    let len = s.window_values().max(1) as f64;
    let (m1, m2) = ((sum_dxh / len) as f32, (sum_dxh_xh / len) as f32);
    for k in 0..cg {
        let gm = gamma[k];
        let (xc, dc, oc) = (&x[k * pixels..], &dy[k * pixels..], &mut dx[k * pixels..]);
        for r in s.segments(wy, wx) {
            for ((o, &v), &d) in oc[r.clone()].iter_mut().zip(&xc[r.clone()]).zip(&dc[r]) {
                let xh = (v - mean) * rstd;
                *o = rstd * (d * gm - m1 - xh * m2);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `[n, c, height, width]`, `groups`, `window`, `silu`.
    fn shape(dims: [usize; 4], groups: usize, window: (usize, usize), silu: bool) -> GroupShape {
        let [n, c, height, width] = dims;
        GroupShape {
            n,
            c,
            height,
            width,
            groups,
            window,
            blend: false,
            silu,
        }
    }

    fn values(len: usize, seed: u32) -> Vec<f32> {
        (0..len)
            .map(|i| {
                let t = (i as u32)
                    .wrapping_mul(2_654_435_761)
                    .wrapping_add(seed.wrapping_mul(97));
                (t >> 8) as f32 / (1u32 << 24) as f32 * 4.0 - 1.5
            })
            .collect()
    }

    fn loss(x: &[f32], s: &GroupShape, gamma: &[f32], beta: &[f32], r: &[f32]) -> f64 {
        let mut y = vec![0.0; x.len()];
        group_norm(x, s, 1e-5, gamma, beta, &mut y);
        y.iter().zip(r).map(|(a, b)| f64::from(a * b)).sum()
    }

    #[test]
    fn forward_normalises_each_group() {
        let s = shape([2, 6, 2, 5], 3, (2, 5), false);
        let x = values(120, 1);
        let (gamma, beta) = (vec![1.0; 6], vec![0.0; 6]);
        let mut y = vec![0.0; 120];
        group_norm(&x, &s, 1e-5, &gamma, &beta, &mut y);
        for block in y.chunks(20) {
            let mean: f64 = block.iter().map(|&v| f64::from(v)).sum::<f64>() / 20.0;
            let var: f64 = block
                .iter()
                .map(|&v| (f64::from(v) - mean).powi(2))
                .sum::<f64>()
                / 20.0;
            assert!(mean.abs() < 1e-6, "{mean}");
            assert!((var - 1.0).abs() < 1e-3, "{var}");
        }
    }

    /// Gradients against central differences of the f64-summed loss.
    fn check_backward(s: GroupShape) {
        let len = s.n * s.c * s.pixels();
        let x = values(len, 2);
        let r = values(len, 3);
        let gamma: Vec<f32> = (0..s.c).map(|i| 0.5 + 0.3 * i as f32).collect();
        let beta: Vec<f32> = (0..s.c).map(|i| 0.1 * i as f32 - 0.2).collect();
        let mut dx = vec![0.0; len];
        let (dgamma, dbeta) = group_norm_backward(&x, &r, &s, 1e-5, &gamma, &mut dx);
        let h = 1e-2f32;
        for i in [0, 7, 23, 31, len - 1] {
            let (mut a, mut b) = (x.clone(), x.clone());
            a[i] += h;
            b[i] -= h;
            let num = (loss(&a, &s, &gamma, &beta, &r) - loss(&b, &s, &gamma, &beta, &r))
                / (2.0 * f64::from(h));
            assert!(
                (f64::from(dx[i]) - num).abs() < 2e-3,
                "dx[{i}] {} vs {num}",
                dx[i]
            );
        }
        for c in 0..s.c {
            let (mut a, mut b) = (gamma.clone(), gamma.clone());
            a[c] += h;
            b[c] -= h;
            let num =
                (loss(&x, &s, &a, &beta, &r) - loss(&x, &s, &b, &beta, &r)) / (2.0 * f64::from(h));
            assert!((f64::from(dgamma[c]) - num).abs() < 2e-3, "dgamma[{c}]");
            let (mut a, mut b) = (beta.clone(), beta.clone());
            a[c] += h;
            b[c] -= h;
            let num = (loss(&x, &s, &gamma, &a, &r) - loss(&x, &s, &gamma, &b, &r))
                / (2.0 * f64::from(h));
            assert!((f64::from(dbeta[c]) - num).abs() < 2e-3, "dbeta[{c}]");
        }
    }
    #[test]
    fn backward_matches_finite_differences() {
        check_backward(shape([2, 4, 2, 3], 2, (2, 3), false));
    }

    #[test]
    fn windowed_backward_matches_finite_differences() {
        check_backward(shape([2, 4, 4, 6], 2, (2, 3), false));
    }

    /// Statistics per window: equal to each window cut out and normalised
    /// as an image of its own.
    #[test]
    fn windows_are_normalised_on_their_own() {
        let s = shape([2, 6, 8, 12], 3, (4, 3), false);
        let x = values(s.n * s.c * s.pixels(), 5);
        let gamma: Vec<f32> = (0..6).map(|i| 0.7 + 0.2 * i as f32).collect();
        let beta: Vec<f32> = (0..6).map(|i| 0.3 - 0.1 * i as f32).collect();
        let mut y = vec![0.0; x.len()];
        group_norm(&x, &s, 1e-5, &gamma, &beta, &mut y);
        let one = GroupShape {
            height: 4,
            width: 3,
            window: (4, 3),
            ..s
        };
        let at = |img: usize, ch: usize, r: usize, col: usize| ((img * 6 + ch) * 8 + r) * 12 + col;
        for (wy, wx) in [(0, 0), (1, 3), (0, 2), (1, 1)] {
            let cut = |v: &[f32]| -> Vec<f32> {
                let mut out = Vec::new();
                for img in 0..2 {
                    for ch in 0..6 {
                        for r in 0..4 {
                            for col in 0..3 {
                                out.push(v[at(img, ch, wy * 4 + r, wx * 3 + col)]);
                            }
                        }
                    }
                }
                out
            };
            let part = cut(&x);
            let mut want = vec![0.0; part.len()];
            group_norm(&part, &one, 1e-5, &gamma, &beta, &mut want);
            let have = cut(&y);
            for (a, b) in want.iter().zip(&have) {
                assert!((a - b).abs() < 1e-5, "window ({wy}, {wx}): {a} vs {b}");
            }
        }
    }

    #[test]
    fn blend_weights_ramp_across_each_border() {
        // Windows of 16, the border at 16 (pixel centres at i + 0.5): the
        // ramp reaches 2 pixels (an eighth of 16) each side of it.
        let w = blend_weights(32, 16, 2);
        assert!(w[..14].iter().all(|&p| p == (0, 0, 0.0)), "{w:?}");
        assert_eq!(w[14], (0, 1, 0.125));
        assert_eq!(w[15], (0, 1, 0.375));
        assert_eq!(w[16], (0, 1, 0.625));
        assert_eq!(w[17], (0, 1, 0.875));
        assert!(w[18..].iter().all(|&p| p == (1, 1, 0.0)), "{w:?}");
        assert_eq!(blend_weights(3, 3, 1), vec![(0, 0, 0.0); 3]);
    }

    /// Blended windows against a direct f64 evaluation: each window's
    /// statistics, mixed bilinearly by [`blend_weights`], applied per pixel;
    /// pixels away from the borders keep their own window's output, those
    /// near them move, and one window is the unblended result.
    #[test]
    fn blended_windows_interpolate_the_statistics() {
        let s = GroupShape {
            blend: true,
            ..shape([2, 4, 16, 24], 2, (8, 8), true)
        };
        let x = values(s.n * s.c * s.pixels(), 11);
        let gamma: Vec<f32> = (0..4).map(|i| 0.6 + 0.25 * i as f32).collect();
        let beta: Vec<f32> = (0..4).map(|i| 0.15 * i as f32 - 0.2).collect();
        let mut y = vec![0.0; x.len()];
        group_norm(&x, &s, 1e-5, &gamma, &beta, &mut y);
        let plain = GroupShape { blend: false, ..s };
        let mut unblended = vec![0.0; x.len()];
        group_norm(&x, &plain, 1e-5, &gamma, &beta, &mut unblended);
        let (h, w, cg) = (16usize, 24usize, 2usize);
        let at = |img: usize, ch: usize, r: usize, c: usize| ((img * 4 + ch) * h + r) * w + c;
        let stats = |img: usize, g: usize, wy: usize, wx: usize| {
            let vals: Vec<f64> = (0..cg)
                .flat_map(|k| (0..8).flat_map(move |r| (0..8).map(move |c| (k, r, c))))
                .map(|(k, r, c)| f64::from(x[at(img, g * cg + k, wy * 8 + r, wx * 8 + c)]))
                .collect();
            let m = vals.iter().sum::<f64>() / vals.len() as f64;
            let v = vals.iter().map(|a| (a - m).powi(2)).sum::<f64>() / vals.len() as f64;
            (m, 1.0 / (v + 1e-5).sqrt())
        };
        let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
        let (rows, cols) = (blend_weights(h, 8, 2), blend_weights(w, 8, 3));
        let bracket = |p: (usize, usize, f32)| (p.0, p.1, f64::from(p.2));
        let (mut worst, mut blended, mut moved) = (0.0f64, 0, 0);
        for img in 0..2 {
            for ch in 0..4 {
                for r in 0..h {
                    for c in 0..w {
                        let ((j0, j1, ty), (i0, i1, tx)) = (bracket(rows[r]), bracket(cols[c]));
                        let st = |j, i| stats(img, ch / cg, j, i);
                        let mix = |f: fn((f64, f64)) -> f64| {
                            let top = lerp(f(st(j0, i0)), f(st(j0, i1)), tx);
                            lerp(top, lerp(f(st(j1, i0)), f(st(j1, i1)), tx), ty)
                        };
                        let (m, rs) = (mix(|p| p.0), mix(|p| p.1));
                        let v = (f64::from(x[at(img, ch, r, c)]) - m) * rs * f64::from(gamma[ch])
                            + f64::from(beta[ch]);
                        let want = v / (1.0 + (-v).exp());
                        worst = worst.max((f64::from(y[at(img, ch, r, c)]) - want).abs());
                        let d = (y[at(img, ch, r, c)] - unblended[at(img, ch, r, c)]).abs();
                        if j0 == j1 && i0 == i1 {
                            assert!(d < 1e-5, "({r}, {c}) away from the borders");
                        } else {
                            blended += 1;
                            moved += usize::from(d > 1e-3);
                        }
                    }
                }
            }
        }
        assert!(worst < 1e-4, "{worst}");
        // The blend moved the pixels near the borders.
        assert!(blended > 0 && moved > blended / 2, "{moved} of {blended}");
        // One window: the plain GroupNorm.
        let one = GroupShape {
            window: (16, 24),
            ..s
        };
        let (mut a, mut b) = (vec![0.0; x.len()], vec![0.0; x.len()]);
        group_norm(&x, &one, 1e-5, &gamma, &beta, &mut a);
        group_norm(
            &x,
            &GroupShape {
                blend: false,
                ..one
            },
            1e-5,
            &gamma,
            &beta,
            &mut b,
        );
        assert_eq!(a, b);
    }

    /// The fused SiLU is SiLU of the plain output.
    #[test]
    fn silu_in_the_same_pass_is_silu_of_the_output() {
        let s = shape([1, 4, 4, 8], 2, (4, 4), false);
        let x = values(128, 9);
        let gamma: Vec<f32> = (0..4).map(|i| 0.8 + 0.4 * i as f32).collect();
        let beta: Vec<f32> = (0..4).map(|i| 0.2 * i as f32 - 0.3).collect();
        let (mut plain, mut fused) = (vec![0.0; 128], vec![0.0; 128]);
        group_norm(&x, &s, 1e-5, &gamma, &beta, &mut plain);
        let fs = GroupShape { silu: true, ..s };
        group_norm(&x, &fs, 1e-5, &gamma, &beta, &mut fused);
        for (p, f) in plain.iter().zip(&fused) {
            let want = f64::from(*p) / (1.0 + (-f64::from(*p)).exp());
            assert!((f64::from(*f) - want).abs() < 1e-5, "{f} vs {want}");
        }
    }
}
