//! The black-level figure: how far a restoration lifts (or sinks) the
//! darkest parts of the picture. A network that learnt calibrated captures
//! and is handed an uncalibrated one adds the camera's black-level error,
//! times the ratio, to every shadow: a magenta-grey veil PSNR barely shows
//! in a bright scene. Issue 36 holds models to within +-0.002 of white.
//!
//! Two figures: the mean (what a viewer sees, clamped output) and the
//! median. The mean counts the residual noise that clamping at zero folds
//! up: a restoration with no offset at all but some residual noise in the
//! shadows lifts the mean (VST + BM3D by +0.010 of white at the A7S2's ISO
//! 1600 x100). Clamping is monotone, so it moves the median only where
//! more than half the dark pixels sit below zero: the median is the offset
//! a restoration adds, whatever noise it leaves.
//!
//! Dark pixels are those whose reference is below 1 % of white over the
//! whole 5 x 5 neighbourhood in their plane: a dark pixel beside a bright
//! one is lifted by any smoothing (selected for being darker than its
//! neighbours, it regresses towards them), which is blur, not a lifted
//! black. (Counting every pixel below 1 %, VST + BM3D, told the offset,
//! had a median of +0.021 of white at the A7S2's ISO 1600 x200.)

use ndarray::ArrayView3;

/// Reference pixels counted as black: below 1 % of white ...
pub const BLACK_BELOW: f32 = 0.01;
/// ... over the (2 r + 1)^2 neighbourhood of this radius.
pub const BLACK_RADIUS: usize = 2;

/// Whether each reference pixel is black over its whole neighbourhood:
/// the maximum over a (2 r + 1) square window (clipped at the edges) below
/// [`BLACK_BELOW`], in each plane; a separable running maximum.
fn dark_regions(reference: ArrayView3<f32>) -> ndarray::Array3<bool> {
    let (c, h, w) = reference.dim();
    let r = BLACK_RADIUS;
    let mut rows = ndarray::Array3::<f32>::zeros((c, h, w));
    for p in 0..c {
        for y in 0..h {
            for x in 0..w {
                let (a, b) = (x.saturating_sub(r), (x + r).min(w - 1));
                rows[[p, y, x]] = (a..=b)
                    .map(|i| reference[[p, y, i]])
                    .fold(f32::NEG_INFINITY, f32::max);
            }
        }
    }
    ndarray::Array3::from_shape_fn((c, h, w), |(p, y, x)| {
        let (a, b) = (y.saturating_sub(r), (y + r).min(h - 1));
        (a..=b)
            .map(|j| rows[[p, j, x]])
            .fold(f32::NEG_INFINITY, f32::max)
            < BLACK_BELOW
    })
}

/// The black-level figures of one restoration, fractions of white.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlackLevel {
    /// Mean of (output clamped to [0, 1]) - reference over the dark pixels.
    pub mean: f64,
    /// Median of the same differences.
    pub median: f64,
    /// How many reference pixels were dark.
    pub pixels: usize,
}

/// Mean and median of (output clamped to [0, 1]) - reference over the
/// pixels whose reference is below [`BLACK_BELOW`] over their whole
/// neighbourhood ([`BLACK_RADIUS`]), as fractions of white;
/// None when no reference pixel is that dark. The mean is accumulated in
/// f64 in pixel order (the same on any machine); the median of an even
/// count is the mean of the middle two.
pub fn black_level(output: ArrayView3<f32>, reference: ArrayView3<f32>) -> Option<BlackLevel> {
    let dark = dark_regions(reference);
    let diffs: Vec<f64> = output
        .iter()
        .zip(reference.iter())
        .zip(dark.iter())
        .filter(|(_, &d)| d)
        .map(|((&o, &r), _)| (o.clamp(0.0, 1.0) - r) as f64)
        .collect();
    let n = diffs.len();
    if n == 0 {
        return None;
    }
    let mean = diffs.iter().sum::<f64>() / n as f64;
    let mut sorted = diffs;
    sorted.sort_unstable_by(f64::total_cmp);
    let median = if n % 2 == 1 {
        sorted[n / 2]
    } else {
        0.5 * (sorted[n / 2 - 1] + sorted[n / 2])
    };
    Some(BlackLevel {
        mean,
        median,
        pixels: n,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    /// Only reference pixels dark over their whole 5 x 5 neighbourhood
    /// count; the output is clamped first.
    #[test]
    fn only_pixels_dark_around_them_count() {
        // A 1 x 8 x 8 plane, black but for a bright pixel at (0, 7): the
        // pixels within 2 of it (rows 0..=2, columns 5..=7) are not dark
        // regions; 64 - 1 - 8 = 55 are.
        let mut reference = Array3::from_elem((1, 8, 8), 0.005f32);
        reference[[0, 0, 7]] = 0.5;
        let mut out = Array3::from_elem((1, 8, 8), 0.007f32);
        out[[0, 7, 0]] = -0.5; // clamped to 0: -0.005
        out[[0, 1, 6]] = 0.9; // beside the bright pixel: not counted
        let b = black_level(out.view(), reference.view()).unwrap();
        assert_eq!(b.pixels, 55);
        let want = (54.0 * 0.002 - 0.005) / 55.0;
        assert!((b.mean - want).abs() < 1e-6, "{b:?}");
        assert!((b.median - 0.002).abs() < 1e-6, "{b:?}");
        let bright = Array3::from_elem((1, 8, 8), 0.5f32);
        assert_eq!(black_level(out.view(), bright.view()), None);
        // A lone dark pixel in a bright plane is not a black region.
        let mut lone = bright.clone();
        lone[[0, 4, 4]] = 0.0;
        assert_eq!(black_level(out.view(), lone.view()), None);
    }

    /// Seeded: a black reference restored as offset + N(0, 0.01^2). The
    /// clamp lifts the mean by sigma / sqrt(2 pi) = 0.0040 with no offset
    /// (0.0045 with +0.001: mu Phi(mu/sigma) + sigma phi(mu/sigma)); the median stays at the offset (sampling
    /// SE ~1.25 sigma / sqrt(n) = 1.2e-4 for n = 10,000; tolerance 5e-4).
    #[test]
    fn the_median_sees_the_offset_not_the_clamped_noise() {
        use pgrf_core::seed::{open01, stream, Domain};
        let mut rng = stream(36, Domain::Pixel, 0, 0);
        let reference = Array3::<f32>::zeros((1, 100, 100));
        for (offset, lift) in [(0.0, 0.00399), (0.001, 0.00451)] {
            let out = reference.mapv(|_| {
                // Box-Muller.
                let (u, v) = (open01(&mut rng), open01(&mut rng));
                let z = (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos();
                (offset + 0.01 * z) as f32
            });
            let b = black_level(out.view(), reference.view()).unwrap();
            assert!((b.median - offset).abs() < 5e-4, "{offset}: {b:?}");
            assert!((b.mean - lift).abs() < 5e-4, "{offset}: {b:?}");
        }
    }
}
