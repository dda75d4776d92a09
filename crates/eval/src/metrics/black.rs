//! The black-level figure: how far a restoration lifts (or sinks) the
//! darkest parts of the picture. A network that learnt calibrated captures
//! and is handed an uncalibrated one adds the camera's black-level error,
//! times the ratio, to every shadow: a magenta-grey veil PSNR barely shows
//! in a bright scene. Issue 36 holds models to within +-0.002 of white.

use ndarray::ArrayView3;

/// Reference pixels counted as black: below 1 % of white.
pub const BLACK_BELOW: f32 = 0.01;

/// Mean of (output clamped to [0, 1]) - reference over the pixels whose
/// reference is below [`BLACK_BELOW`], as a fraction of white, and how many
/// pixels that was; None when no reference pixel is that dark. Accumulated
/// in f64 in pixel order (the same on any machine).
pub fn black_lift(output: ArrayView3<f32>, reference: ArrayView3<f32>) -> Option<(f64, usize)> {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for (&o, &r) in output.iter().zip(reference.iter()) {
        if r < BLACK_BELOW {
            sum += (o.clamp(0.0, 1.0) - r) as f64;
            n += 1;
        }
    }
    (n > 0).then(|| (sum / n as f64, n))
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    /// Only the dark reference pixels count; the output is clamped first.
    #[test]
    fn only_pixels_dark_in_the_reference_count() {
        let mut reference = Array3::from_elem((1, 2, 2), 0.5f32);
        reference[[0, 0, 0]] = 0.0;
        reference[[0, 0, 1]] = 0.005;
        let mut out = Array3::from_elem((1, 2, 2), 0.9f32);
        out[[0, 0, 0]] = 0.004;
        out[[0, 0, 1]] = -0.5;
        let (lift, n) = black_lift(out.view(), reference.view()).unwrap();
        assert_eq!(n, 2);
        assert!(
            (lift - (0.004 + (0.0 - 0.005)) / 2.0).abs() < 1e-9,
            "{lift}"
        );
        let bright = Array3::from_elem((1, 2, 2), 0.5f32);
        assert_eq!(black_lift(out.view(), bright.view()), None);
    }
}
