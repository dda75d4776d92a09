//! GroupNorm with its affine, forward and backward, each a few passes over
//! one contiguous `(channels / groups) * pixels` block per (image, group),
//! in parallel over blocks.
//!
//! burn 0.21 builds GroupNorm (and pgrf's folded form, `pgrf_nn::norm`) from
//! a dozen tensor operations whose backward repeats them; here the forward
//! reads the input twice (mean, then variance about it) and writes once, and
//! the backward reads input and output gradient twice and writes once.
//! Sums run in eight f32 lanes over spans of 1024 values and in f64 across
//! spans; biased variance, epsilon inside the root, as burn.

use rayon::prelude::*;

/// Layout of a GroupNorm input: `n` images of `c` channels of `pixels`
/// values, `groups` groups of `c / groups` consecutive channels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GroupShape {
    /// Images.
    pub n: usize,
    /// Channels (a multiple of `groups`).
    pub c: usize,
    /// Pixels per channel.
    pub pixels: usize,
    /// Groups.
    pub groups: usize,
}

impl GroupShape {
    fn block(&self) -> usize {
        self.c / self.groups * self.pixels
    }

    fn check(&self, len: usize) {
        assert!(
            self.groups > 0 && self.c.is_multiple_of(self.groups),
            "groups must divide channels"
        );
        assert_eq!(len, self.n * self.c * self.pixels, "tensor size");
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

/// Mean and 1 / sqrt(variance + eps) of one block (two passes: the mean,
/// then squared deviations from it).
fn stats(block: &[f32], eps: f64) -> (f32, f32) {
    let len = block.len().max(1) as f64;
    let mean = (sum_by(block, |v| v) / len) as f32;
    let var = sum_by(block, |v| (v - mean) * (v - mean)) / len;
    (mean, (1.0 / (var + eps).sqrt()) as f32)
}

/// `out = (x - mean) / sqrt(var + eps) * gamma[c] + beta[c]`, statistics per
/// (image, group).
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
    let (block, cg) = (s.block(), s.c / s.groups);
    out.par_chunks_mut(block.max(1))
        .zip(x.par_chunks(block.max(1)))
        .enumerate()
        .for_each(|(b, (o, x))| {
            let (mean, rstd) = stats(x, eps);
            let g = b % s.groups;
            for (k, (o, x)) in o.chunks_mut(s.pixels).zip(x.chunks(s.pixels)).enumerate() {
                let ch = g * cg + k;
                let scale = rstd * gamma[ch];
                let shift = beta[ch] - mean * scale;
                for (o, &v) in o.iter_mut().zip(x) {
                    *o = v * scale + shift;
                }
            }
        });
}

/// Gradients of [`group_norm`] from its input `x` and output gradient `dy`:
/// writes `dx` and returns `(dgamma, dbeta)`, each `c` long. With `xh` the
/// normalised input and `dxh = dy * gamma[c]`, per block: `dx = rstd * (dxh
/// - mean(dxh) - xh * mean(dxh * xh))`.
pub fn group_norm_backward(
    x: &[f32],
    dy: &[f32],
    s: &GroupShape,
    eps: f64,
    gamma: &[f32],
    dx: &mut [f32],
) -> (Vec<f32>, Vec<f32>) {
    s.check(x.len());
    assert!(dy.len() == x.len() && dx.len() == x.len(), "gradient sizes");
    assert_eq!(gamma.len(), s.c, "affine size");
    let (block, cg) = (s.block(), s.c / s.groups);
    // Per (image, channel) sums of dy and dy * xh, for the affine's gradients.
    let partial: Vec<(Vec<f64>, Vec<f64>)> = dx
        .par_chunks_mut(block.max(1))
        .zip(x.par_chunks(block.max(1)).zip(dy.par_chunks(block.max(1))))
        .enumerate()
        .map(|(b, (dx, (x, dy)))| {
            let (mean, rstd) = stats(x, eps);
            let g = b % s.groups;
            let (mut sum_dy, mut sum_dy_xh) = (vec![0.0f64; cg], vec![0.0f64; cg]);
            let (mut sum_dxh, mut sum_dxh_xh) = (0.0f64, 0.0f64);
            for (k, (x, dy)) in x.chunks(s.pixels).zip(dy.chunks(s.pixels)).enumerate() {
                let gm = f64::from(gamma[g * cg + k]);
                let (a, b2) = sums_dy(x, dy, mean, rstd);
                sum_dy[k] = a;
                sum_dy_xh[k] = b2;
                sum_dxh += a * gm;
                sum_dxh_xh += b2 * gm;
            }
            let len = block.max(1) as f64;
            let (m1, m2) = ((sum_dxh / len) as f32, (sum_dxh_xh / len) as f32);
            for (k, ((dx, x), dy)) in dx
                .chunks_mut(s.pixels)
                .zip(x.chunks(s.pixels))
                .zip(dy.chunks(s.pixels))
                .enumerate()
            {
                let gm = gamma[g * cg + k];
                for ((o, &v), &d) in dx.iter_mut().zip(x).zip(dy) {
                    let xh = (v - mean) * rstd;
                    *o = rstd * (d * gm - m1 - xh * m2);
                }
            }
            (sum_dy, sum_dy_xh)
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

#[cfg(test)]
mod tests {
    use super::*;

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
        let s = GroupShape {
            n: 2,
            c: 6,
            pixels: 10,
            groups: 3,
        };
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
    #[test]
    fn backward_matches_finite_differences() {
        let s = GroupShape {
            n: 2,
            c: 4,
            pixels: 6,
            groups: 2,
        };
        let x = values(48, 2);
        let r = values(48, 3);
        let gamma: Vec<f32> = (0..4).map(|i| 0.5 + 0.3 * i as f32).collect();
        let beta: Vec<f32> = (0..4).map(|i| 0.1 * i as f32 - 0.2).collect();
        let mut dx = vec![0.0; 48];
        let (dgamma, dbeta) = group_norm_backward(&x, &r, &s, 1e-5, &gamma, &mut dx);
        let h = 1e-2f32;
        for i in [0, 7, 23, 31, 47] {
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
        for c in 0..4 {
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
}
