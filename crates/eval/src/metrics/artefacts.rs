//! Artefacts a photographer sees at 100 % and PSNR barely counts (issue 51,
//! item 6):
//!
//! - **speckles**: pixels whose error stands out from their neighbours'
//!   where the reference is flat (the flow model's ring-shaped speckles).
//!   Each pixel's error minus the median error of its 8 same-plane
//!   neighbours (so that smooth errors, a halo of blur beside an edge or
//!   a tint, do not count) is compared with the robust standard deviation
//!   of that difference over the flat regions (1.4826 x its median absolute
//!   deviation); beyond [`SPECKLE_SIGMAS`] of them it is a speckle. White
//!   Gaussian error gives almost none (none in the tests' 61,440 pixels).
//! - **seams**: a straight line at the border of the tiles or internal
//!   windows a network ran on. The step of the error between neighbouring
//!   columns (the median over planes and rows of |e(x) - e(x - 1)|: the
//!   median, so that the few rows where an edge of the picture crosses the
//!   column do not count) at each border column, against the median step
//!   over all columns; rows likewise. A restoration without seams has a
//!   ratio near 1 at every border. Measure it on a frame whose reference
//!   has no noise of its own and no structure on the grid (a seeded
//!   procedural scene): a picture edge that runs along a border column is
//!   a step of the error too.
//!
//! Both take the output clamped to [0, 1], as every figure here does.

use super::error::MetricError;
use super::Result;
use ndarray::ArrayView3;
use pgrf_core::stats::{median, median_and_robust_sd};

/// A flat-region pixel further than this many robust standard deviations
/// from the median error is a speckle.
pub const SPECKLE_SIGMAS: f64 = 5.0;

/// A reference pixel is in a flat region when its 5 x 5 same-plane
/// neighbourhood spans less than this fraction of white.
pub const FLAT_SPAN: f32 = 0.02;

/// The speckle count of one restoration.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Speckles {
    /// Flat-region pixels beyond [`SPECKLE_SIGMAS`] robust deviations.
    pub count: usize,
    /// Pixels in flat regions (what the count is out of).
    pub flat_pixels: usize,
    /// The robust standard deviation of the flat regions' error about its
    /// neighbourhood's median, fraction of white.
    pub sigma: f64,
}

/// The worst seam of one restoration.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Seams {
    /// The largest border step over the median step, rows or columns.
    pub worst: f64,
    /// Where: "column" or "row" and the packed index of the border.
    pub axis: &'static str,
    /// Packed index of the column (or row) right of (below) the border.
    pub at: usize,
    /// The median step over all columns (rows for a row border).
    pub median_step: f64,
}

impl std::fmt::Display for Speckles {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} of {} flat-region pixels beyond {SPECKLE_SIGMAS} robust sd ({:.5} of white)",
            self.count, self.flat_pixels, self.sigma
        )
    }
}

impl std::fmt::Display for Seams {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "worst {:.2}x the median step, at {} {} (median step {:.5})",
            self.worst, self.axis, self.at, self.median_step
        )
    }
}

/// Equal shapes, not empty, every value finite ([`super::input::pair`]).
fn check(output: ArrayView3<f32>, reference: ArrayView3<f32>) -> Result<()> {
    super::input::pair(output, reference).map(|_| ())
}

/// The error (clamped output - reference) at each pixel.
fn error(output: ArrayView3<f32>, reference: ArrayView3<f32>) -> ndarray::Array3<f64> {
    ndarray::Zip::from(&output)
        .and(&reference)
        .map_collect(|&o, &r| (o.clamp(0.0, 1.0) - r) as f64)
}

/// Whether each reference pixel's 5 x 5 same-plane neighbourhood (clipped
/// at the edges) spans less than [`FLAT_SPAN`].
fn flat(reference: ArrayView3<f32>) -> ndarray::Array3<bool> {
    let (_, h, w) = reference.dim();
    ndarray::Array3::from_shape_fn(reference.dim(), |(p, y, x)| {
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for j in y.saturating_sub(2)..=(y + 2).min(h - 1) {
            for i in x.saturating_sub(2)..=(x + 2).min(w - 1) {
                let v = reference[[p, j, i]];
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
        hi - lo < FLAT_SPAN
    })
}

/// Each pixel's error minus the median error of its (up to) 8 same-plane
/// neighbours: the pixel itself left out, so that for white error the two
/// are independent and the difference keeps Gaussian tails. The neighbours
/// are held on the stack: this runs once per pixel.
fn local_deviation(e: &ndarray::Array3<f64>) -> ndarray::Array3<f64> {
    let (_, h, w) = e.dim();
    ndarray::Array3::from_shape_fn(e.dim(), |(p, y, x)| {
        let mut n = [0.0f64; 8];
        let mut k = 0;
        for j in y.saturating_sub(1)..=(y + 1).min(h - 1) {
            for i in x.saturating_sub(1)..=(x + 1).min(w - 1) {
                if (j, i) != (y, x) {
                    n[k] = e[[p, j, i]];
                    k += 1;
                }
            }
        }
        // A 1 x 1 plane has no neighbour: nothing to stand out from.
        if k == 0 {
            0.0
        } else {
            e[[p, y, x]] - median(&mut n[..k])
        }
    })
}

/// Count the speckles of `output` against `reference` (same `(C, H, W)`).
pub fn speckles(output: ArrayView3<f32>, reference: ArrayView3<f32>) -> Result<Speckles> {
    check(output, reference)?;
    let e = local_deviation(&error(output, reference));
    let mask = flat(reference);
    let mut flat_errors: Vec<f64> = e
        .iter()
        .zip(mask.iter())
        .filter(|(_, &m)| m)
        .map(|(&v, _)| v)
        .collect();
    let flat_pixels = flat_errors.len();
    if flat_pixels == 0 {
        return Ok(Speckles {
            count: 0,
            flat_pixels,
            sigma: 0.0,
        });
    }
    let (centre, sigma) = median_and_robust_sd(&mut flat_errors);
    let count = if sigma > 0.0 {
        flat_errors
            .iter()
            .filter(|v| (*v - centre).abs() > SPECKLE_SIGMAS * sigma)
            .count()
    } else {
        0
    };
    Ok(Speckles {
        count,
        flat_pixels,
        sigma,
    })
}

/// Median over planes and the other axis of |e(k) - e(k - 1)| for k =
/// 1..n along `axis` (1: rows, 2: columns); entry k - 1 is the step before k.
fn steps(e: &ndarray::Array3<f64>, axis: usize) -> Vec<f64> {
    let (c, h, w) = e.dim();
    let (n, m) = if axis == 2 { (w, h) } else { (h, w) };
    (1..n)
        .map(|k| {
            let mut d = Vec::with_capacity(c * m);
            for p in 0..c {
                for i in 0..m {
                    let (a, b) = if axis == 2 {
                        (e[[p, i, k]], e[[p, i, k - 1]])
                    } else {
                        (e[[p, k, i]], e[[p, k - 1, i]])
                    };
                    d.push((a - b).abs());
                }
            }
            median(&mut d)
        })
        .collect()
}

/// The worst seam of `output` against `reference` at the borders every
/// `period` packed pixels (the tile or window grid: 128 for the shipped
/// PGRF's windows), rows and columns, the grid starting `offset` pixels
/// before the frame (borders at k period - offset; `pgrf enhance`'s grid
/// starts its mirrored margin before the frame, `pgrf_nn`'s `EDGE_MARGIN`).
pub fn seams(
    output: ArrayView3<f32>,
    reference: ArrayView3<f32>,
    period: usize,
    offset: usize,
) -> Result<Seams> {
    check(output, reference)?;
    let (_, h, w) = output.dim();
    if period < 2 || offset >= period || (period - offset >= w && period - offset >= h) {
        return Err(MetricError::InvalidOption(format!(
            "a border period of {period} starting {offset} before the frame has no border inside a {w}x{h} frame (the offset must be below the period)"
        )));
    }
    let e = error(output, reference);
    let mut worst = Seams {
        worst: 0.0,
        axis: "column",
        at: 0,
        median_step: 0.0,
    };
    for (axis, name) in [(2usize, "column"), (1, "row")] {
        let s = steps(&e, axis);
        let med = median(&mut s.clone());
        let mut k = period - offset;
        while k < s.len() + 1 {
            let ratio = if med > 0.0 { s[k - 1] / med } else { 0.0 };
            if ratio > worst.worst {
                worst = Seams {
                    worst: ratio,
                    axis: name,
                    at: k,
                    median_step: med,
                };
            }
            k += period;
        }
    }
    Ok(worst)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A smooth reference (flat almost everywhere at this scale) and a
    /// restoration of it with Gaussian error of sd 0.004, seeded.
    fn pair(seed: u64) -> (Array3<f32>, Array3<f32>) {
        let (h, w) = (96, 160);
        let reference = Array3::from_shape_fn((4, h, w), |(p, y, x)| {
            0.2 + 0.05 * p as f32 + 0.1 * (y as f32 / h as f32) + 0.05 * (x as f32 / w as f32)
        });
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let n = Normal::new(0.0f32, 0.004).unwrap();
        let output = reference.mapv(|v| v + n.sample(&mut rng));
        (output, reference)
    }

    #[test]
    fn gaussian_error_has_no_speckle_and_no_seam() {
        let (o, r) = pair(51);
        let s = speckles(o.view(), r.view()).unwrap();
        assert_eq!(s.flat_pixels, 4 * 96 * 160);
        // Expected 5.7e-7 x 61,440 = 0.04 pixels beyond 5 sigma.
        assert_eq!(s.count, 0);
        // e - median of 8 others: sd about 1.1 of the error's own (the
        // median of 8 has variance ~0.18 sigma^2).
        assert!(s.sigma > 0.0041 && s.sigma < 0.0049, "{}", s.sigma);
        let m = seams(o.view(), r.view(), 32, 0).unwrap();
        // Steps of white noise: the median |d| of 4 x 96 (columns) or 4 x
        // 160 (rows) samples, sd ~ 6 % of it, so the largest of 7 borders
        // stays below 1.15.
        assert!(m.worst < 1.15, "{m:?}");
    }

    #[test]
    fn planted_speckles_are_counted_exactly_and_smooth_errors_are_not() {
        let (mut o, r) = pair(52);
        // A smooth bump of 0.05 (12 sd) over a 40 x 40 area: a halo or a
        // tint, not a speckle.
        for ((_, y, x), v) in o.indexed_iter_mut() {
            let d2 = ((y as f32 - 60.0).powi(2) + (x as f32 - 100.0).powi(2)) / 200.0;
            *v += 0.05 * (-d2).exp();
        }
        assert_eq!(speckles(o.view(), r.view()).unwrap().count, 0);
        for (k, &(y, x)) in [(10, 10), (40, 77), (90, 150), (50, 3), (3, 120)]
            .iter()
            .enumerate()
        {
            o[[k % 4, y, x]] += if k % 2 == 0 { 0.05 } else { -0.05 };
        }
        let s = speckles(o.view(), r.view()).unwrap();
        assert_eq!(s.count, 5, "{s:?}");
    }

    #[test]
    fn a_level_jump_at_window_borders_is_a_seam() {
        let (mut o, r) = pair(53);
        // Windows of 32 whose levels differ by 0.008 (two sd of the error):
        // the median step across a border nearly doubles (|N(2, 2)| against
        // |N(0, 2)| in units of the sd: medians 2.2 and 0.95).
        for ((_, y, x), v) in o.indexed_iter_mut() {
            if ((x / 32) + (y / 32)) % 2 == 1 {
                *v += 0.008;
            }
        }
        let m = seams(o.view(), r.view(), 32, 0).unwrap();
        assert!(m.worst > 1.7, "{m:?}");
        assert_eq!(m.at % 32, 0);
        assert!(seams(o.view(), r.view(), 1, 0).is_err());
        assert!(seams(o.view(), r.view(), 500, 0).is_err());
        assert!(seams(o.view(), r.view(), 32, 32).is_err());
        // The same windows starting 4 pixels before the frame: found with
        // that offset, missed without it.
        let (mut o, r) = pair(53);
        for ((_, y, x), v) in o.indexed_iter_mut() {
            if (((x + 4) / 32) + ((y + 4) / 32)) % 2 == 1 {
                *v += 0.008;
            }
        }
        let shifted = seams(o.view(), r.view(), 32, 4).unwrap();
        assert!(shifted.worst > 1.7 && shifted.at % 32 == 28, "{shifted:?}");
        assert!(seams(o.view(), r.view(), 32, 0).unwrap().worst < 1.3);
    }
}
