//! The noise of a frame nobody calibrated, from the frame itself: a robust
//! fit of the signal-dependent (Poisson-Gaussian) variance S x + O of the
//! signal x normalised to [0, 1], after Foi et al., "Practical
//! Poissonian-Gaussian noise modeling and fitting for single-image raw-data"
//! (IEEE TIP 2008), simplified.
//!
//! Each packed plane is cut into 8 x 8 blocks. In a block, the noise is read
//! from the residual of each pixel against the mean of its four neighbours
//! (a discrete Laplacian: for independent noise of variance v its variance
//! is 1.25 v, while smooth signal cancels) through the median absolute
//! deviation, which an edge crossing a few pixels does not move; the
//! block's level is its mean. Blocks touching the clipping at white, or
//! with more than a few samples at the frame's lowest value (a camera that
//! clips at black), are left out: their variance is not S x + O. The blocks
//! are grouped by level into bins of equal count, and in each bin the lower
//! quartile of the block variances stands for the bin (textured blocks only
//! ever add variance; the quartile of a chi-square-like spread of flat
//! blocks sits below their mean, corrected by a factor measured for 8 x 8
//! blocks); S and O come from a weighted least-squares line through the bins,
//! each held non-negative.

use crate::error::{NoiseError, Result};
use ndarray::ArrayView3;

/// Side of the blocks, packed pixels.
const BLOCK: usize = 8;
/// Bins of blocks by level.
const BINS: usize = 24;
/// Fewest usable blocks for a fit.
const MIN_BLOCKS: usize = 64;
/// Samples at or above this fraction of white count as clipped.
const WHITE_CLIP: f32 = 0.98;

/// The fit of a frame's noise: variance S x + O of the normalised signal x.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlindFit {
    /// S: variance per unit of normalised signal (K / range).
    pub s: f64,
    /// O: signal-independent variance ((sigma_read / range)^2).
    pub o: f64,
    /// Blocks the fit used.
    pub blocks: usize,
}

impl BlindFit {
    /// K in DN per electron and the read noise in DN, on a scale of `range`
    /// DN (white - black).
    pub fn in_dn(&self, range: f64) -> (f64, f64) {
        (self.s * range, self.o.sqrt() * range)
    }
}

/// Median of `v` (reordered); 0 for an empty slice.
fn median(v: &mut [f32]) -> f32 {
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    *m
}

/// One block's level and noise variance from the two green planes, or
/// None where clipping leaves it unusable. The two greens of a Bayer quad
/// are diagonal neighbours in the mosaic, so their difference cancels
/// nearly all image detail while their independent noise adds up (variance
/// 2 v): the residual is far freer of texture than any within-plane one. A
/// constant offset between them (a per-plane dark level) is taken out with
/// the block's median difference; the variance is the mean square of the
/// rest, with samples beyond 4 robust standard deviations (an edge along
/// the diagonal) left out. Not a median-based variance: at a fraction of an
/// electron per pixel the Poisson noise is discrete and its MAD says little.
fn block_stats(
    g1: &ndarray::ArrayView2<f32>,
    g2: &ndarray::ArrayView2<f32>,
    (y0, x0): (usize, usize),
    floor: f32,
    scratch: &mut Vec<f32>,
) -> Option<(f64, f64)> {
    scratch.clear();
    let mut sum = 0.0f64;
    let mut at_floor = 0usize;
    for y in y0..y0 + BLOCK {
        for x in x0..x0 + BLOCK {
            let (a, b) = (g1[(y, x)], g2[(y, x)]);
            if a >= WHITE_CLIP || b >= WHITE_CLIP {
                return None;
            }
            at_floor += (a <= floor) as usize + (b <= floor) as usize;
            sum += (a + b) as f64;
            scratch.push(a - b);
        }
    }
    // A camera that clips at black piles samples on its lowest value.
    if at_floor * 20 > 2 * BLOCK * BLOCK {
        return None;
    }
    let n = BLOCK * BLOCK;
    let diffs: Vec<f32> = scratch.clone();
    let m = median(scratch);
    for r in scratch.iter_mut() {
        *r = (*r - m).abs();
    }
    let sigma = (median(scratch) as f64 * 1.4826).max(1e-12);
    let (mut sq, mut kept) = (0.0f64, 0usize);
    for d in diffs {
        let r = (d - m) as f64;
        if r.abs() <= 4.0 * sigma {
            sq += r * r;
            kept += 1;
        }
    }
    if kept < n / 2 {
        return None;
    }
    Some((sum / (2 * n) as f64, sq / kept as f64 / 2.0))
}

/// Fit S x + O to the packed normalised frame `packed` `(4, h, w)` in R,
/// G1, B, G2 order (each plane minus its black level, over white - black;
/// not clipped). The greens carry the estimate (`block_stats`); K and the
/// read noise in DN are the sensor's, the same for every plane.
pub fn fit(packed: ArrayView3<f32>) -> Result<BlindFit> {
    let (c, h, w) = packed.dim();
    if c != 4 {
        return Err(NoiseError::Estimate(format!(
            "{c} planes; the estimate reads a Bayer frame's two greens"
        )));
    }
    let floor = packed.iter().copied().fold(f32::INFINITY, f32::min);
    if !floor.is_finite() {
        return Err(NoiseError::Estimate(
            "the frame has no finite samples".into(),
        ));
    }
    // Samples equal to the lowest one (to f32 rounding of the
    // normalisation) are a black clip, not a noise draw.
    let floor = floor + floor.abs() * 1e-6 + 1e-9;
    let g1 = packed.index_axis(ndarray::Axis(0), 1);
    let g2 = packed.index_axis(ndarray::Axis(0), 3);
    let mut blocks: Vec<(f64, f64)> = Vec::new();
    let mut scratch = Vec::with_capacity(BLOCK * BLOCK);
    for by in 0..h / BLOCK {
        for bx in 0..w / BLOCK {
            if let Some(b) = block_stats(&g1, &g2, (by * BLOCK, bx * BLOCK), floor, &mut scratch) {
                blocks.push(b);
            }
        }
    }
    if blocks.len() < MIN_BLOCKS {
        return Err(NoiseError::Estimate(format!(
            "{} usable 8x8 blocks (of unclipped signal), at least {MIN_BLOCKS} needed",
            blocks.len()
        )));
    }
    blocks.sort_by(|a, b| a.0.total_cmp(&b.0));
    let per_bin = blocks.len() / BINS.min(blocks.len() / 8).max(1);
    let mut points: Vec<(f64, f64, f64)> = Vec::new();
    for chunk in blocks.chunks(per_bin) {
        if chunk.len() < per_bin / 2 {
            continue;
        }
        let level = chunk.iter().map(|b| b.0).sum::<f64>() / chunk.len() as f64;
        let mut vars: Vec<f32> = chunk.iter().map(|b| b.1 as f32).collect();
        vars.sort_by(|a, b| a.total_cmp(b));
        let q = vars[(vars.len() as f64 * QUANTILE) as usize] as f64 / QUANTILE_TO_MEAN;
        points.push((level, q, chunk.len() as f64));
    }
    let (s, o) = weighted_line(&points);
    Ok(BlindFit {
        s,
        o,
        blocks: blocks.len(),
    })
}

/// Which quantile of a bin's block variances stands for the bin: low, so
/// that textured blocks (which only add variance) are passed over.
const QUANTILE: f64 = 0.25;

/// That quantile of 8 x 8 blocks' MAD-based variance over the true
/// variance, for flat blocks of Gaussian noise: measured by the test
/// `the_quantile_factor_is_what_flat_gaussian_blocks_give` (20,000 blocks).
const QUANTILE_TO_MEAN: f64 = 0.864;

/// Least squares of v = S x + O through `(x, v, weight)` points, each point
/// weighted by its count over its variance squared (the variance of a
/// variance estimate grows with its square); S and O held non-negative.
fn weighted_line(points: &[(f64, f64, f64)]) -> (f64, f64) {
    let solve = |pts: &[(f64, f64, f64)]| {
        let (mut sw, mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for &(x, v, n) in pts {
            let wt = n / (v * v).max(1e-30);
            sw += wt;
            sx += wt * x;
            sy += wt * v;
            sxx += wt * x * x;
            sxy += wt * x * v;
        }
        let det = sw * sxx - sx * sx;
        if det.abs() < 1e-300 {
            return (0.0, sy / sw.max(1e-300));
        }
        let s = (sw * sxy - sx * sy) / det;
        (s, (sy - s * sx) / sw)
    };
    let (s, o) = solve(points);
    if s < 0.0 {
        // No signal dependence measurable: all of it is read noise.
        let mean =
            points.iter().map(|p| p.1 * p.2).sum::<f64>() / points.iter().map(|p| p.2).sum::<f64>();
        return (0.0, mean.max(0.0));
    }
    if o < 0.0 {
        // A line through the origin: S = sum(w x v) / sum(w x^2).
        let (mut num, mut den) = (0.0, 0.0);
        for &(x, v, n) in points {
            let wt = n / (v * v).max(1e-30);
            num += wt * x * v;
            den += wt * x * x;
        }
        return ((num / den.max(1e-300)).max(0.0), 0.0);
    }
    (s, o)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    use rand_xoshiro::Xoshiro256PlusPlus;

    #[test]
    fn the_quantile_factor_is_what_flat_gaussian_blocks_give() {
        // 20,000 flat 8x8 blocks of two greens with unit Gaussian noise:
        // the bins' quantile of the block estimates over the true variance.
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(7);
        let n = Normal::new(0.0f32, 1.0).unwrap();
        let (h, w) = (8 * 100, 8 * 200);
        let mut plane =
            || ndarray::Array2::from_shape_fn((h, w), |_| 0.5 + 0.01 * n.sample(&mut rng));
        let (g1, g2) = (plane(), plane());
        let mut vars = Vec::new();
        let mut scratch = Vec::new();
        for by in 0..100 {
            for bx in 0..200 {
                if let Some((_, v)) =
                    block_stats(&g1.view(), &g2.view(), (by * 8, bx * 8), -1.0, &mut scratch)
                {
                    vars.push((v / 1e-4) as f32);
                }
            }
        }
        vars.sort_by(|a, b| a.total_cmp(b));
        let q = vars[(vars.len() as f64 * QUANTILE) as usize] as f64;
        assert_eq!(vars.len(), 20_000);
        assert!(
            (q - QUANTILE_TO_MEAN).abs() < 0.01,
            "quantile {QUANTILE}: {q}"
        );
    }

    /// A smooth ramp with Poisson-Gaussian noise of known S and O: the fit
    /// finds the gain S and the read noise sqrt(O) within 5 %.
    #[test]
    fn a_noisy_ramp_gives_back_its_noise() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        let n = Normal::new(0.0f64, 1.0).unwrap();
        let (s, o) = (2e-4, 4e-6);
        let img = Array3::from_shape_fn((4, 256, 384), |(_, y, x)| {
            let clean = 0.02 + 0.6 * (x as f64 / 384.0) * (0.5 + 0.5 * y as f64 / 256.0);
            (clean + (s * clean + o).sqrt() * n.sample(&mut rng)) as f32
        });
        let f = fit(img.view()).unwrap();
        assert!((f.s / s - 1.0).abs() < 0.05, "S {} vs {s}", f.s);
        assert!(((f.o / o).sqrt() - 1.0).abs() < 0.05, "O {} vs {o}", f.o);
    }

    #[test]
    fn a_frame_without_usable_blocks_is_refused() {
        let img = Array3::from_elem((4, 16, 16), 1.0f32);
        assert!(fit(img.view()).is_err());
    }
}
