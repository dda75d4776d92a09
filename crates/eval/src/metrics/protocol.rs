//! The evaluation protocol: which transformations happen between a network's
//! packed output and the PSNR/SSIM numbers, stated explicitly so a printed
//! score always comes with how it was measured.
//!
//! The ELD protocol (ELD's `ELDModelBase.eval`, `tensor2im` and
//! `quality_assess`; also used by PMN and the PGRF paper), step by step, all
//! per element and in float32 like ELD's tensors:
//!
//! 1. output clamped to [0, 1];
//! 2. optionally multiplied by the illuminance gain ([`super::correct`]);
//! 3. output and reference multiplied by 255 as floats (no rounding to 8 bits)
//!    and clipped to [0, 255] (ELD's `tensor2im`);
//! 4. PSNR with data range 255 and SSIM with scikit-image's defaults (7x7
//!    uniform window, channel mean) on those values, accumulated in f64.
//!
//! The steps run inside the metric kernels as a per-element map, so no scaled
//! copy of either image is made, and PSNR's squared differences come out of
//! the SSIM pass (one read of each image after the gain fit).

use super::correct::gain_of;
use super::input::{check_data_range, pair};
use super::psnr::psnr_from_mse;
use super::ssim::{channel_mean, ssim_and_sse_mapped, SsimOptions};
use super::Result;
use ndarray::ArrayView3;

/// How a pair is measured. [`Protocol::eld`] is the published protocol.
#[derive(Clone, Debug, PartialEq)]
pub struct Protocol {
    /// Clamp the output to [0, 1] first, and clip both scaled images to
    /// [0, `data_range`] (ELD's `tensor2im`). Without it, values are measured as
    /// given (scaled only), which is plain scikit-image on `x * data_range`.
    pub clamp: bool,
    /// Apply ELD's least-squares brightness gain to the output. The gain is
    /// fitted on, and applied to, the output clamped to [0, 1] whatever
    /// `clamp` says, because that is what ELD's correction does.
    pub illuminance_correct: bool,
    /// Images in [0, 1] are multiplied by this (as f32) and PSNR/SSIM use it as
    /// their data range: 255 in ELD's protocol.
    pub data_range: f32,
}

impl Protocol {
    /// ELD's protocol, with or without the illuminance correction.
    pub const fn eld(illuminance_correct: bool) -> Self {
        Protocol {
            clamp: true,
            illuminance_correct,
            data_range: 255.0,
        }
    }

    /// One line saying how the numbers were measured.
    pub fn describe(&self) -> String {
        let r = self.data_range;
        let clamp = if self.clamp {
            format!("output clamped [0,1], x{r} float (no rounding) clipped [0,{r}]")
        } else {
            format!("no clamping, x{r} float (no rounding)")
        };
        let corr = if self.illuminance_correct {
            "illuminance correction on (least-squares gain over reference != 1)"
        } else {
            "illuminance correction off"
        };
        format!(
            "{clamp}, {corr}, PSNR data_range {r}, SSIM 7x7 uniform K1 0.01 K2 0.03 sample covariance, channel mean"
        )
    }
}

impl Default for Protocol {
    fn default() -> Self {
        Protocol::eld(false)
    }
}

/// Scores of one pair under one protocol.
#[derive(Clone, Debug, PartialEq)]
pub struct Scores {
    /// dB; `f64::INFINITY` when the measured images are identical.
    pub psnr: f64,
    /// SSIM, mean over channels, in [-1, 1] (1 when identical).
    pub ssim: f64,
    /// The illuminance gain applied, when the protocol corrects.
    pub gain: Option<f64>,
    /// How it was measured, one line (channel count, then [`Protocol::describe`]).
    pub protocol: String,
}

/// PSNR and SSIM of `output` against `reference`, both packed `(C, H, W)`
/// (values nominally in [0, 1]), under `protocol`.
pub fn evaluate(
    output: ArrayView3<f32>,
    reference: ArrayView3<f32>,
    protocol: &Protocol,
) -> Result<Scores> {
    let range = protocol.data_range;
    check_data_range(range as f64)?;
    let p = pair(output, reference)?;
    let gain = protocol
        .illuminance_correct
        .then(|| gain_of(&p.output, &p.reference).gain);
    // ELD multiplies a float32 tensor by the gain; multiplying by 1.0 when
    // there is no correction is exact, so one map serves both cases.
    let g32 = gain.unwrap_or(1.0) as f32;
    let clamp = protocol.clamp;
    let clamp_first = clamp || protocol.illuminance_correct;
    let fo = move |o: f32| -> f64 {
        let o = if clamp_first { clip(o, 1.0) } else { o };
        let v = (g32 * o) * range;
        (if clamp { clip(v, range) } else { v }) as f64
    };
    let fr = move |r: f32| -> f64 {
        let v = r * range;
        (if clamp { clip(v, range) } else { v }) as f64
    };
    let opts = SsimOptions::skimage(range as f64);
    let (per, sse) = ssim_and_sse_mapped(&p.output, &p.reference, p.dims, fo, fr, &opts)?;
    let mse = sse / p.output.len() as f64;
    Ok(Scores {
        psnr: psnr_from_mse(mse, range as f64),
        ssim: channel_mean(&per),
        gain,
        protocol: format!("packed {}-channel, {}", p.dims.0, protocol.describe()),
    })
}

/// `v` clamped to [0, hi]; inputs are finite (checked), so this select form
/// (one min and one max instruction) equals `f32::clamp` and numpy's `clip`.
#[inline(always)]
fn clip(v: f32, hi: f32) -> f32 {
    let v = if v < 0.0 { 0.0 } else { v };
    if v > hi {
        hi
    } else {
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    #[test]
    fn describe_names_every_choice() {
        let d = Protocol::eld(true).describe();
        for want in [
            "clamped [0,1]",
            "x255",
            "correction on",
            "data_range 255",
            "7x7",
        ] {
            assert!(d.contains(want), "{d}");
        }
        assert!(Protocol::eld(false).describe().contains("correction off"));
    }

    #[test]
    fn clamping_matters_only_when_asked() {
        // Output 1.5 where the reference is 1: clamped, the images are equal.
        let reference = Array3::from_elem((1, 8, 8), 1.0f32);
        let out = Array3::from_elem((1, 8, 8), 1.5f32);
        let s = evaluate(out.view(), reference.view(), &Protocol::eld(false)).unwrap();
        assert_eq!((s.psnr, s.ssim), (f64::INFINITY, 1.0));
        let raw = Protocol {
            clamp: false,
            ..Protocol::eld(false)
        };
        let s = evaluate(out.view(), reference.view(), &raw).unwrap();
        let want = 10.0 * (255.0f64 * 255.0 / (127.5f64 * 127.5)).log10();
        assert!((s.psnr - want).abs() < 1e-12, "{} vs {want}", s.psnr);
    }
}
