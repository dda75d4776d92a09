//! Peak signal-to-noise ratio, computed as scikit-image's
//! `peak_signal_noise_ratio(reference, output, data_range=R)`:
//! `10 log10(R^2 / MSE)` with the mean squared error over every element of
//! every channel.
//!
//! The papers pgrf compares with report this number on x255 float images with
//! `R = 255`; [`crate::evaluate`] prepares images that way. Here the values are
//! taken as given (widened to f64; each squared difference and the sum are
//! f64, as scikit-image does for float64 inputs).
//!
//! Identical images have MSE 0 and PSNR `+inf` (scikit-image divides by zero
//! and returns `inf` too). The value is returned as `f64::INFINITY`, never
//! clamped to a made-up ceiling: callers that print JSON decide how to show it.

use super::input::{check_data_range, pair, CHUNK};
use super::sum::sum2;
use super::Result;
use ndarray::ArrayView3;
use rayon::prelude::*;

/// Mean squared error over all elements, in f64.
pub(crate) fn mse(output: ArrayView3<f32>, reference: ArrayView3<f32>) -> Result<f64> {
    let p = pair(output, reference)?;
    Ok(mse_mapped(&p.output, &p.reference, widen, widen))
}

/// PSNR in dB of `output` against `reference` for a signal spanning
/// `data_range` (255 for x255 images). `+inf` when the images are identical.
pub fn psnr(output: ArrayView3<f32>, reference: ArrayView3<f32>, data_range: f64) -> Result<f64> {
    check_data_range(data_range)?;
    Ok(psnr_from_mse(mse(output, reference)?, data_range))
}

/// `10 log10(R^2 / mse)`, the same expression (and order) as scikit-image.
pub(crate) fn psnr_from_mse(mse: f64, data_range: f64) -> f64 {
    if mse == 0.0 {
        return f64::INFINITY;
    }
    10.0 * ((data_range * data_range) / mse).log10()
}

pub(crate) fn widen(v: f32) -> f64 {
    v as f64
}

/// Mean of `(fx(x) - fy(y))^2`; `fx`/`fy` turn stored values into the values
/// measured (identity, or the protocol's clamp/gain/x255), so no scaled copy
/// of a 12-megapixel image is ever allocated.
pub(crate) fn mse_mapped<FX, FY>(x: &[f32], y: &[f32], fx: FX, fy: FY) -> f64
where
    FX: Fn(f32) -> f64 + Sync,
    FY: Fn(f32) -> f64 + Sync,
{
    debug_assert_eq!(x.len(), y.len());
    let partial: Vec<f64> = x
        .par_chunks(CHUNK)
        .zip(y.par_chunks(CHUNK))
        .map(|(a, b)| {
            sum2(a, b, |a, b| {
                let d = fx(a) - fy(b);
                d * d
            })
        })
        .collect();
    partial.iter().sum::<f64>() / x.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    #[test]
    fn hand_computed_value() {
        // Two of eight elements differ by 3 and 4: MSE = (9 + 16) / 8.
        let a = Array3::<f32>::zeros((2, 2, 2));
        let mut b = a.clone();
        b[[0, 1, 0]] = 3.0;
        b[[1, 0, 1]] = -4.0;
        let want = 10.0 * (255.0f64 * 255.0 / (25.0 / 8.0)).log10();
        assert_eq!(psnr(b.view(), a.view(), 255.0).unwrap(), want);
        assert_eq!(mse(a.view(), b.view()).unwrap(), 25.0 / 8.0);
    }

    #[test]
    fn identical_images_are_infinite() {
        let a = Array3::from_shape_fn((4, 5, 6), |(c, y, x)| (c + y * x) as f32 * 0.01);
        assert_eq!(psnr(a.view(), a.view(), 255.0).unwrap(), f64::INFINITY);
    }

    #[test]
    fn bad_data_range_is_refused() {
        let a = Array3::<f32>::zeros((1, 2, 2));
        for r in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let e = psnr(a.view(), a.view(), r).unwrap_err().to_string();
            assert!(e.contains("data range"), "{e}");
        }
    }
}
