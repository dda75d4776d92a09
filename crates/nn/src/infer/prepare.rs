//! From a decoded dark frame to the network's input, the way the training
//! pairs were made: packed, normalised by each plane's black and white
//! levels, optionally minus the calibrated dark shading, multiplied by the
//! exposure ratio and clamped to [0, 1].

use crate::error::{NnError, Result};
use ndarray::{Array3, Axis};
use pgrf_raw::{pack_normalized, RawFrame};

/// The network input of a dark capture: `(4, H/2, W/2)` packed R, G1, B, G2,
/// each plane normalised by its black and white levels, multiplied by
/// `ratio` (the exposure ratio, > 0) and clamped to [0, 1]. `dark_dn`:
/// per-pixel dark level above black in DN (packed like the frame), e.g. a
/// calibration's fixed pattern plus dark current, subtracted before the
/// ratio.
pub fn network_input(
    frame: &RawFrame,
    ratio: f32,
    dark_dn: Option<&Array3<f32>>,
) -> Result<Array3<f32>> {
    if !(ratio.is_finite() && ratio > 0.0) {
        return Err(NnError::BadSetting {
            flag: "--ratio",
            message: format!("the exposure ratio must be a positive number, got {ratio}"),
        });
    }
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
    x.par_mapv_inplace(|v| (v * ratio).clamp(0.0, 1.0));
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
    Ok((target_exposure_s / t * gain) as f32)
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
    fn input_is_normalised_amplified_and_clamped() {
        let f = frame();
        let x = network_input(&f, 100.0, None).unwrap();
        // Pixel (0, 0) = 512 -> 0; pixel (0, 2) = 532 -> 20/15871 * 100.
        assert_eq!(x[[0, 0, 0]], 0.0);
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
    }
}
