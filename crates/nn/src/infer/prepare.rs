//! From a decoded dark frame to the network's input, the way the training
//! pairs were made: packed, normalised by each plane's black and white
//! levels, optionally minus the calibrated dark shading, multiplied by the
//! exposure ratio and clipped at 1; values below black stay negative (a
//! network that reads them clamped clamps them itself: `Net::as_read`).

use crate::error::{NnError, Result};
use ndarray::{Array3, Axis};
use pgrf_raw::{pack_normalized, RawFrame};

/// The network input of a dark capture: `(4, H/2, W/2)` packed R, G1, B, G2,
/// each plane normalised by its black and white levels, multiplied by
/// `ratio` (the exposure ratio, > 0) and clipped at 1, values below black
/// kept (negative). `dark_dn`:
/// per-pixel dark level above black in DN (packed like the frame), e.g. a
/// calibration's fixed pattern plus dark current, subtracted before the
/// ratio.
pub fn network_input(
    frame: &RawFrame,
    ratio: f32,
    dark_dn: Option<&Array3<f32>>,
) -> Result<Array3<f32>> {
    check_ratio(ratio)?;
    amplify(normalised_minus_dark(frame, dark_dn)?, ratio)
}

/// Refuse an exposure ratio that is not a positive number.
fn check_ratio(ratio: f32) -> Result<()> {
    if ratio.is_finite() && ratio > 0.0 {
        return Ok(());
    }
    Err(NnError::BadSetting {
        flag: "--ratio",
        message: format!("the exposure ratio must be a positive number, got {ratio}"),
    })
}

/// A packed, normalised dark capture made the network's input: multiplied
/// by `ratio` (the exposure ratio, > 0) and clipped at 1, values below
/// black kept (what [`network_input`] does after packing).
pub fn amplify(mut packed: Array3<f32>, ratio: f32) -> Result<Array3<f32>> {
    check_ratio(ratio)?;
    packed.par_mapv_inplace(|v| (v * ratio).min(1.0));
    Ok(packed)
}

/// `frame` packed, each plane normalised by its black and white levels,
/// minus `dark_dn` (DN above black, packed like the frame) on the same
/// scale; not amplified, not clamped.
fn normalised_minus_dark(frame: &RawFrame, dark_dn: Option<&Array3<f32>>) -> Result<Array3<f32>> {
    let mut x = pack_normalized(frame, false)?;
    if let Some(dark) = dark_dn {
        if dark.shape() != x.shape() {
            return Err(NnError::SizeMismatch(format!(
                "dark shading packs to {:?}, the frame to {:?}",
                dark.shape(),
                x.shape()
            )));
        }
        for (plane, (mut xp, dp)) in x
            .axis_iter_mut(Axis(0))
            .zip(dark.axis_iter(Axis(0)))
            .enumerate()
        {
            let scale = 1.0 / (frame.white as f32 - frame.black[plane]);
            ndarray::Zip::from(&mut xp)
                .and(&dp)
                .par_for_each(|v, &d| *v -= d * scale);
        }
    }
    Ok(x)
}

/// The exposure ratio that brings a capture to a target exposure, by
/// exposure time x ISO (the ELD convention): `target_exposure_s` / the
/// file's exposure time, times `target_iso` / the file's ISO when a target
/// ISO is given. Refuses files that do not record what is needed.
pub fn ratio_from_exposure(
    frame: &RawFrame,
    target_exposure_s: f64,
    target_iso: Option<u32>,
) -> Result<f32> {
    let t = frame
        .exposure_s
        .filter(|t| *t > 0.0)
        .ok_or_else(|| NnError::BadSetting {
            flag: "--ratio",
            message: "the file records no exposure time; give --ratio instead".into(),
        })?;
    let iso = frame.iso.filter(|i| *i > 0);
    let gain = match (target_iso, iso) {
        (None, _) => 1.0,
        (Some(ti), Some(i)) => ti as f64 / i as f64,
        (Some(_), None) => {
            return Err(NnError::BadSetting {
                flag: "--target-iso",
                message: "the file records no ISO; --target-iso needs it (or give --ratio)".into(),
            })
        }
    };
    if !(target_exposure_s.is_finite() && target_exposure_s > 0.0) {
        return Err(NnError::BadSetting {
            flag: "--target-exposure",
            message: format!(
                "--target-exposure must be a positive number of seconds, got {target_exposure_s}"
            ),
        });
    }
    let ratio = target_exposure_s / t * gain;
    let range = pgrf_noise::pair::RATIO_RANGE;
    if !(ratio.is_finite() && range.contains(&(ratio as f32))) {
        let shown = pgrf_core::number::shown;
        return Err(NnError::BadSetting {
            flag: "--target-exposure",
            message: format!(
                "--target-exposure {} s over the file's exposure of {} s is a ratio of {}; the exposure ratio must be from {} to {}",
                shown(target_exposure_s),
                shown(t),
                shown(ratio),
                range.start(),
                range.end()
            ),
        });
    }
    Ok(ratio as f32)
}

/// Where `--ratio auto` brings a frame: its mean level (black-subtracted,
/// brightest 1 % left out) at 1/8 of white, three stops below clipping,
/// about where a camera's metering puts an average scene in its raw data.
pub const AUTO_TARGET: f64 = 0.125;
/// The largest ratio `--ratio auto` picks: the top of the range the
/// built-in models were trained on.
pub const AUTO_MAX_RATIO: f32 = 300.0;

/// The ratio `--ratio auto` picked for a frame, and why.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AutoRatio {
    /// The exposure ratio, in [1, [`AUTO_MAX_RATIO`]].
    pub ratio: f32,
    /// The frame's level it was computed from, fraction of white.
    pub level: f64,
}

impl AutoRatio {
    /// "auto: mean level 0.00131 of white brought to 0.125", with the
    /// limit named when the ratio was held at it.
    pub fn describe(&self) -> String {
        let held = if self.ratio >= AUTO_MAX_RATIO {
            format!(", held at the largest, {AUTO_MAX_RATIO}")
        } else if self.ratio <= 1.0 {
            ", held at 1 (the frame is not dark)".to_string()
        } else {
            String::new()
        };
        format!(
            "auto: mean level {:.3e} of white brought to {AUTO_TARGET}{held}",
            self.level
        )
    }
}

/// `--ratio auto`: the exposure ratio that brings the frame's mean level
/// (each plane normalised by its black and white levels, minus `dark_dn`
/// like [`network_input`], the brightest 1 % of a regular subsample left out
/// so that a street lamp does not darken the night) to [`AUTO_TARGET`],
/// within [1, [`AUTO_MAX_RATIO`]]. Refuses a frame with no signal above
/// black (a lens-cap frame): no ratio makes it a photograph.
pub fn auto_ratio(frame: &RawFrame, dark_dn: Option<&Array3<f32>>) -> Result<AutoRatio> {
    let x = normalised_minus_dark(frame, dark_dn)?;
    // Every 7th value (7 is prime to the plane and row sizes that matter:
    // the subsample takes every plane and column phase).
    let step = if x.len() > 1 << 20 { 7 } else { 1 };
    let mut sample: Vec<f32> = x
        .iter()
        .step_by(step)
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    if sample.is_empty() {
        return Err(NnError::BadSetting {
            flag: "--ratio",
            message: "the frame has no pixels to measure; give --ratio".into(),
        });
    }
    let keep = (sample.len() * 99).div_ceil(100).max(1);
    let (low, _, _) = sample.select_nth_unstable_by(keep - 1, f32::total_cmp);
    let kept = low.len() + 1;
    let sum: f64 = low.iter().map(|&v| v as f64).sum::<f64>() + sample[keep - 1] as f64;
    let level = sum / kept as f64;
    // Below a millionth of white the mean is the noise's, not a scene's.
    if level.is_nan() || level <= 1e-6 {
        return Err(NnError::BadSetting {
            flag: "--ratio",
            message: format!(
                "--ratio auto: the frame has no signal above black (mean level {level:.2e} of white); give --ratio"
            ),
        });
    }
    let ratio = (AUTO_TARGET / level).clamp(1.0, AUTO_MAX_RATIO as f64) as f32;
    Ok(AutoRatio { ratio, level })
}

#[cfg(test)]
mod tests {
    use super::*;
    use pgrf_raw::Cfa;

    fn frame() -> RawFrame {
        let mosaic: Vec<u16> = (0..16).map(|i| 512 + i * 10).collect();
        let mut f = RawFrame::from_mosaic(4, 4, mosaic, Cfa::Rggb, [512.0; 4], 16383).unwrap();
        f.exposure_s = Some(0.01);
        f.iso = Some(1600);
        f
    }

    #[test]
    fn input_is_normalised_amplified_and_clipped_at_white_only() {
        let mut f = frame();
        // Pixel (1, 1) (packed plane B at (0, 0)) recorded 7 DN below black.
        f.mosaic[5] = 505;
        let x = network_input(&f, 100.0, None).unwrap();
        // Pixel (0, 0) = 512 -> 0; pixel (0, 2) = 532 -> 20/15871 * 100.
        assert_eq!(x[[0, 0, 0]], 0.0);
        // Below black stays below, amplified like the rest: -7/15871 * 100.
        assert!(
            (x[[2, 0, 0]] + 700.0 / 15871.0).abs() < 1e-6,
            "{}",
            x[[2, 0, 0]]
        );
        assert!((x[[0, 0, 1]] - 2000.0 / 15871.0).abs() < 1e-6);
        let big = network_input(&f, 1e4, None).unwrap();
        assert_eq!(big[[2, 1, 1]], 1.0);
        assert!(network_input(&f, 0.0, None).is_err());
        assert!(network_input(&f, f32::NAN, None).is_err());
    }

    #[test]
    fn dark_shading_is_subtracted_in_dn() {
        let f = frame();
        let dark = Array3::from_elem((4, 2, 2), 10.0f32);
        let x = network_input(&f, 1.0, Some(&dark)).unwrap();
        // (532 - 512 - 10) / 15871 at pixel (0, 2).
        assert!((x[[0, 0, 1]] - 10.0 / 15871.0).abs() < 1e-7);
        assert!(network_input(&f, 1.0, Some(&Array3::zeros((4, 1, 2)))).is_err());
    }

    #[test]
    fn ratio_from_exposure_and_iso() {
        let f = frame();
        assert!((ratio_from_exposure(&f, 1.0, None).unwrap() - 100.0).abs() < 1e-4);
        assert!((ratio_from_exposure(&f, 1.0, Some(3200)).unwrap() - 200.0).abs() < 1e-3);
        let mut g = f.clone();
        g.exposure_s = None;
        assert!(ratio_from_exposure(&g, 1.0, None).is_err());
        // 1e30 s over 0.01 s, or 1e-9 s: ratios no camera records.
        for t in [1e30, 1e-9] {
            let e = ratio_from_exposure(&f, t, None).unwrap_err().to_string();
            assert!(
                e.contains("from 1 to 10000") && e.contains("exposure of 0.01 s"),
                "{e}"
            );
        }
    }
}

#[cfg(test)]
mod auto_tests {
    use super::*;
    use pgrf_raw::Cfa;

    /// A 64 x 64 frame at `level` of white above black 512 (white 16383),
    /// with `lamps` pixels at white.
    fn flat(level: f64, lamps: usize) -> RawFrame {
        let v = 512 + (level * 15871.0).round() as u16;
        let mut m = vec![v; 64 * 64];
        for p in m.iter_mut().take(lamps) {
            *p = 16383;
        }
        RawFrame::from_mosaic(64, 64, m, Cfa::Rggb, [512.0; 4], 16383).unwrap()
    }

    /// The ratio brings the mean to 1/8 of white; 1 % of lamps at white
    /// change nothing (a plain mean would drop the ratio by ~6x); limits
    /// and a frame at black.
    #[test]
    fn auto_ratio_meters_the_frame_and_ignores_lamps() {
        let a = auto_ratio(&flat(0.001, 0), None).unwrap();
        assert!((a.level - 16.0 / 15871.0).abs() < 1e-9, "{a:?}");
        assert!((a.ratio as f64 - 0.125 / a.level).abs() < 1e-3, "{a:?}");
        let lit = auto_ratio(&flat(0.001, 40), None).unwrap();
        assert_eq!(lit.ratio, a.ratio);
        assert_eq!(auto_ratio(&flat(0.3, 0), None).unwrap().ratio, 1.0);
        let deep = auto_ratio(&flat(0.0001, 0), None).unwrap();
        assert_eq!(deep.ratio, AUTO_MAX_RATIO);
        assert!(
            deep.describe().contains("held at the largest"),
            "{}",
            deep.describe()
        );
        let e = auto_ratio(&flat(0.0, 0), None).unwrap_err().to_string();
        assert!(e.contains("no signal above black"), "{e}");
        // Dark shading is subtracted first: 10 DN of it leaves 6 DN.
        let dark = Array3::from_elem((4, 32, 32), 10.0f32);
        let d = auto_ratio(&flat(0.001, 0), Some(&dark)).unwrap();
        assert!((d.level - 6.0 / 15871.0).abs() < 1e-9, "{d:?}");
    }
}
