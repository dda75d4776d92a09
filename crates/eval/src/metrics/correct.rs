//! ELD's "illuminance correction": one least-squares brightness gain that
//! maps the (clamped) output onto the reference, fitted over the reference's
//! unsaturated pixels, applied before the metrics.
//!
//! Why it exists: a denoiser trained on synthetic pairs can be right up to a
//! global brightness factor (black-level error, exposure-ratio rounding), and
//! ELD reports PSNR/SSIM both with and without removing that factor. Its
//! `IlluminanceCorrect.correct` (models/ELD_model.py in the ELD release) is:
//!
//! ```text
//! predict = clamp(predict, 0, 1)
//! m = source != 1                     # saturated reference pixels say nothing about brightness
//! gain = dot(predict[m], source[m]) / dot(predict[m], predict[m])
//! output = gain * predict
//! ```
//!
//! pgrf mirrors that exactly, with two documented differences:
//! - the dot products are summed in f64 (ELD's `torch.dot` on float32 sums in
//!   float32), so the gain is the exact least-squares one to ~1e-15;
//! - ELD divides 0 by 0 and carries NaN on when no reference pixel is
//!   unsaturated or the output is zero on all of them; pgrf then uses gain 1
//!   (no correction), and says so through [`IlluminanceGain::pixels`] and a
//!   `den` of zero rather than poisoning the scores.
//!
//! The mask is exactly `reference != 1.0` as ELD writes it: references come
//! from `pack_normalized(frame, clip = true)`, where every saturated sample is
//! clamped to exactly 1.0.

use super::input::{pair, CHUNK};
use super::Result;
use ndarray::{Array3, ArrayView3};
use rayon::prelude::*;

/// The fitted gain and what it was fitted on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IlluminanceGain {
    /// `sum(o r) / sum(o o)` over unsaturated reference pixels, `o` the output
    /// clamped to [0, 1]; exactly 1.0 when that is undefined (see `pixels`, `den`).
    pub gain: f64,
    /// Number of reference pixels different from 1.0 (the fit's support).
    pub pixels: usize,
    /// `sum(o o)` over those pixels; zero means the output was black there and
    /// the gain fell back to 1.
    pub(crate) den: f64,
}

impl IlluminanceGain {
    /// Whether a gain could be fitted (some unsaturated pixel, non-black output).
    #[cfg(test)]
    fn fitted(&self) -> bool {
        self.pixels > 0 && self.den > 0.0
    }
}

/// Fit ELD's brightness gain of `output` against `reference`.
pub fn illuminance_gain(
    output: ArrayView3<f32>,
    reference: ArrayView3<f32>,
) -> Result<IlluminanceGain> {
    let p = pair(output, reference)?;
    Ok(gain_of(&p.output, &p.reference))
}

/// ELD's correction: `gain * clamp(output, 0, 1)` (the product in f32, as
/// ELD's float32 tensors do), with the gain it used.
pub fn illuminance_correct(
    output: ArrayView3<f32>,
    reference: ArrayView3<f32>,
) -> Result<(Array3<f32>, IlluminanceGain)> {
    let g = illuminance_gain(output.view(), reference)?;
    let g32 = g.gain as f32;
    let corrected = output.mapv(|o| g32 * o.clamp(0.0, 1.0));
    Ok((corrected, g))
}

/// `(clamp(o, 0, 1), r, 1)` for an unsaturated reference pixel, `(0, r, 0)`
/// for a saturated one.
#[inline(always)]
fn masked(o: f32, r: f32) -> (f64, f64, usize) {
    let keep = r != 1.0;
    let o = if o < 0.0 { 0.0 } else { o };
    let o = if o > 1.0 { 1.0 } else { o };
    (if keep { o as f64 } else { 0.0 }, r as f64, keep as usize)
}

pub(crate) fn gain_of(output: &[f32], reference: &[f32]) -> IlluminanceGain {
    let partial: Vec<(f64, f64, usize)> = output
        .par_chunks(CHUNK)
        .zip(reference.par_chunks(CHUNK))
        .map(|(o, r)| {
            // One pass, four lanes of each sum; masked pixels contribute
            // o = 0 through a select rather than a branch, so it vectorises.
            let (mut num, mut den, mut n) = ([0.0f64; 4], [0.0f64; 4], [0usize; 4]);
            let split = o.len() - o.len() % 4;
            for (oc, rc) in o[..split].chunks_exact(4).zip(r[..split].chunks_exact(4)) {
                for l in 0..4 {
                    let (ov, rv, m) = masked(oc[l], rc[l]);
                    num[l] += ov * rv;
                    den[l] += ov * ov;
                    n[l] += m;
                }
            }
            let (mut num, mut den, mut n) = (
                (num[0] + num[1]) + (num[2] + num[3]),
                (den[0] + den[1]) + (den[2] + den[3]),
                n.iter().sum::<usize>(),
            );
            for (&ov, &rv) in o[split..].iter().zip(&r[split..]) {
                let (ov, rv, m) = masked(ov, rv);
                num += ov * rv;
                den += ov * ov;
                n += m;
            }
            (num, den, n)
        })
        .collect();
    let (num, den, pixels) = partial
        .iter()
        .fold((0.0, 0.0, 0), |(a, b, c), &(x, y, z)| (a + x, b + y, c + z));
    let gain = if pixels > 0 && den > 0.0 {
        num / den
    } else {
        1.0
    };
    IlluminanceGain { gain, pixels, den }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn degenerate_fits_fall_back_to_one() {
        // Every reference pixel saturated: nothing to fit on.
        let out = Array3::from_elem((1, 3, 3), 0.4f32);
        let sat = Array3::from_elem((1, 3, 3), 1.0f32);
        let g = illuminance_gain(out.view(), sat.view()).unwrap();
        assert_eq!((g.gain, g.pixels, g.fitted()), (1.0, 0, false));
        // Black output (after clamping: negative values are black too).
        let black = Array3::from_elem((1, 3, 3), -0.2f32);
        let reference = Array3::from_elem((1, 3, 3), 0.3f32);
        let (c, g) = illuminance_correct(black.view(), reference.view()).unwrap();
        assert_eq!((g.gain, g.pixels, g.den), (1.0, 9, 0.0));
        assert!(c.iter().all(|&v| v == 0.0));
    }

    #[test]
    fn output_is_clamped_before_fitting() {
        // Output 2.0 clamps to 1.0, so the gain onto a 0.5 reference is 0.5.
        let out = Array3::from_elem((1, 2, 2), 2.0f32);
        let reference = Array3::from_elem((1, 2, 2), 0.5f32);
        let (c, g) = illuminance_correct(out.view(), reference.view()).unwrap();
        assert_eq!(g.gain, 0.5);
        assert!(c.iter().all(|&v| v == 0.5));
    }
}
