//! Unprocessing (Brooks et al., CVPR 2019, "Unprocessing Images for Learned
//! Raw Denoising"): an ordinary sRGB photo turned into the RAW mosaic a given
//! camera would have recorded of the scene, so that denoisers can train on
//! natural images of any camera without clean RAWs of it.
//!
//! Each step inverts one step of pgrf's own preview pipeline
//! ([`crate::render_preview`]), so that unprocessing and then previewing
//! gives the photo back: inverse sRGB transfer, inverse camera -> sRGB
//! matrix (from the camera's DNG colour matrix), inverse white balance
//! (division by the camera's white-balance multipliers), an exposure factor,
//! then the camera's CFA phase and black/white levels.

use crate::color::{camera_from_srgb, srgb_decode};
use crate::error::{RawError, Result};
use crate::photo::Photo;
use crate::{Cfa, ColorMatrix, RawFrame};
use rayon::prelude::*;

/// The camera an image is unprocessed into: its colour, mosaic and levels.
#[derive(Clone, Debug)]
pub struct CameraSpace {
    /// XYZ -> camera matrix (DNG ColorMatrix; D65 preferred).
    pub xyz_to_cam: [[f32; 3]; 3],
    /// White-balance multipliers R, G, B of the scene's illuminant (the
    /// preview multiplies by them, unprocessing divides).
    pub wb: [f32; 3],
    /// The CFA phase of the mosaic.
    pub cfa: Cfa,
    /// Black level per plane R, G1, B, G2, DN.
    pub black: [f32; 4],
    /// White level, DN.
    pub white: u32,
}

impl CameraSpace {
    /// The camera space of a decoded RAW file: its colour matrix, as-shot
    /// white balance, CFA and levels. Refused (with the reason) when the
    /// file has no colour matrix or no white balance.
    pub fn of(frame: &RawFrame) -> Result<CameraSpace> {
        let cm = frame.color_matrix().ok_or_else(|| {
            RawError::Invalid(
                "the camera file has no colour matrix: cannot unprocess into its space".into(),
            )
        })?;
        let wb = frame.wb.ok_or_else(|| {
            RawError::Invalid(
                "the camera file has no as-shot white balance: cannot unprocess into its space"
                    .into(),
            )
        })?;
        Ok(CameraSpace {
            xyz_to_cam: cm.xyz_to_cam,
            wb,
            cfa: frame.cfa,
            black: frame.black,
            white: frame.white,
        })
    }
}

/// Unprocess an sRGB-encoded photo into `camera`'s RAW space, scaled by
/// `exposure` (linear light; 1 keeps the photo's brightness). Values that
/// leave the sensor's range are clipped at white and at 0 DN. The result
/// carries the camera's matrix and white balance so that its preview
/// renders the photo again.
pub fn unprocess(photo: &Photo, camera: &CameraSpace, exposure: f32) -> Result<RawFrame> {
    let (rgb, width, height) = (&photo.rgb, photo.width, photo.height);
    if width < 2 || height < 2 || rgb.len() != width * height * 3 {
        return Err(RawError::Invalid(format!(
            "unprocess: {} values for a {width}x{height} RGB image",
            rgb.len()
        )));
    }
    if !(exposure.is_finite() && exposure > 0.0) {
        return Err(RawError::Invalid(format!(
            "unprocess: exposure must be a positive number, got {exposure}"
        )));
    }
    if camera.wb.iter().any(|g| !(g.is_finite() && *g > 0.0)) {
        return Err(RawError::Invalid(format!(
            "unprocess: white-balance multipliers must be positive, got {:?}",
            camera.wb
        )));
    }
    let m = camera_from_srgb(&camera.xyz_to_cam).ok_or_else(|| {
        RawError::Invalid("unprocess: the colour matrix cannot be used (a row sums to zero)".into())
    })?;
    let channel_of_plane = [0usize, 1, 2, 1];
    let mut mosaic = vec![0u16; width * height];
    mosaic
        .par_chunks_mut(width)
        .enumerate()
        .for_each(|(r, row)| {
            for (c, v) in row.iter_mut().enumerate() {
                let px = &rgb[(r * width + c) * 3..(r * width + c) * 3 + 3];
                let lin = [srgb_decode(px[0]), srgb_decode(px[1]), srgb_decode(px[2])];
                let p = camera.cfa.plane_at(r, c);
                let ch = channel_of_plane[p];
                let balanced = (0..3).map(|k| m[ch][k] * lin[k] as f64).sum::<f64>();
                let x = balanced / camera.wb[ch] as f64 * exposure as f64;
                let range = camera.white as f64 - camera.black[p] as f64;
                let dn = (camera.black[p] as f64 + x.min(1.0) * range).round();
                *v = dn.clamp(0.0, camera.white as f64) as u16;
            }
        });
    let mut frame = RawFrame::from_mosaic(
        width,
        height,
        mosaic,
        camera.cfa,
        camera.black,
        camera.white,
    )?;
    frame.wb = Some(camera.wb);
    frame.color_matrices = vec![ColorMatrix {
        illuminant: "D65".into(),
        xyz_to_cam: camera.xyz_to_cam,
    }];
    Ok(frame)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{render_preview, PreviewOptions};

    /// The Sony A7S2's D65 matrix and a daylight white balance, as the
    /// built-in profile and chart use.
    fn a7s2(cfa: Cfa) -> CameraSpace {
        CameraSpace {
            xyz_to_cam: crate::chart::A7S2_D65_MATRIX,
            wb: [2.4, 1.0, 1.7],
            cfa,
            black: [512.0; 4],
            white: 16383,
        }
    }

    /// A moderately saturated test photo: colour gradients with texture
    /// (sinusoids of 12- to 20-pixel periods, different per channel), which
    /// the demosaic reproduces only to within its interpolation error.
    fn photo(w: usize, h: usize) -> Photo {
        let mut v = Vec::with_capacity(w * h * 3);
        for r in 0..h {
            for c in 0..w {
                let (x, y) = (c as f32 / w as f32, r as f32 / h as f32);
                let (fc, fr) = (c as f32, r as f32);
                let tex = |p: f32, q: f32| 0.06 * (fc / p + fr / q).sin();
                v.push(0.25 + 0.45 * x + tex(3.2, 2.5));
                v.push(0.30 + 0.35 * y + tex(2.9, 3.1));
                v.push(0.55 - 0.25 * x + 0.15 * y + tex(2.2, 3.4));
            }
        }
        Photo {
            width: w,
            height: h,
            rgb: v,
        }
    }

    fn psnr(a: &[f32], b: &[f32]) -> f64 {
        let mse = a
            .iter()
            .zip(b)
            .map(|(x, y)| ((x - y) as f64).powi(2))
            .sum::<f64>()
            / a.len() as f64;
        10.0 * (1.0 / mse).log10()
    }

    /// Unprocess then pgrf's preview brings the photo back, for all four
    /// CFA phases: > 40 dB on the interior (the demosaic's border rows are
    /// left out), every pixel here unclipped.
    #[test]
    fn preview_of_the_unprocessed_photo_is_the_photo() {
        let (w, h) = (96, 64);
        let src = photo(w, h);
        for cfa in [Cfa::Rggb, Cfa::Bggr, Cfa::Grbg, Cfa::Gbrg] {
            let frame = unprocess(&src, &a7s2(cfa), 1.0).unwrap();
            assert!(frame
                .mosaic
                .iter()
                .all(|&v| v > 512 && (v as u32) < frame.white));
            let back = render_preview(&frame, &PreviewOptions::default()).unwrap();
            assert_eq!((back.width, back.height), (w, h));
            let inner = |img: &[f32]| -> Vec<f32> {
                (4..h - 4)
                    .flat_map(|r| (4..w - 4).map(move |c| (r, c)))
                    .flat_map(|(r, c)| img[(r * w + c) * 3..(r * w + c) * 3 + 3].to_vec())
                    .collect()
            };
            let p = psnr(&inner(&back.rgb), &inner(&src.rgb));
            assert!(p > 40.0, "{cfa:?}: {p:.2} dB");
        }
    }

    /// The colour steps are not the identity: a neutral grey lands on the
    /// camera's white-balance ratio (G / R = 2.4 in DN above black), and
    /// the exposure factor scales linear light.
    #[test]
    fn neutral_grey_follows_the_white_balance_and_exposure() {
        let grey = Photo {
            width: 4,
            height: 4,
            rgb: vec![0.5f32; 4 * 4 * 3],
        };
        let f = unprocess(&grey, &a7s2(Cfa::Rggb), 1.0).unwrap();
        let at = |r: usize, c: usize| f.mosaic[r * 4 + c] as f64 - 512.0;
        let (red, green) = (at(0, 0), at(0, 1));
        assert!((green / red - 2.4).abs() < 0.01, "{green} / {red}");
        // Linear 0.5^2.2-ish grey: sRGB 0.5 decodes to 0.21404.
        let expect = 0.214_041 * (16383.0 - 512.0);
        assert!((green - expect).abs() < 1.0, "{green} vs {expect}");
        let half = unprocess(&grey, &a7s2(Cfa::Rggb), 0.5).unwrap();
        let g2 = half.mosaic[1] as f64 - 512.0;
        assert!((g2 - expect / 2.0).abs() < 1.0);
    }

    #[test]
    fn bad_arguments_are_refused() {
        let cam = a7s2(Cfa::Rggb);
        let img = |n: usize| Photo {
            width: 2,
            height: 2,
            rgb: vec![0.5; n],
        };
        assert!(unprocess(&img(10), &cam, 1.0).is_err());
        assert!(unprocess(&img(12), &cam, 0.0).is_err());
        assert!(unprocess(&img(12), &cam, f32::NAN).is_err());
        let mut no_wb = cam.clone();
        no_wb.wb = [0.0, 1.0, 1.0];
        assert!(unprocess(&img(12), &no_wb, 1.0).is_err());
        let mut frame = unprocess(&img(12), &cam, 1.0).unwrap();
        frame.color_matrices.clear();
        let e = CameraSpace::of(&frame).unwrap_err().to_string();
        assert!(e.contains("no colour matrix"), "{e}");
    }
}
