//! Unprocessing (Brooks et al., CVPR 2019, "Unprocessing Images for Learned
//! Raw Denoising"): an ordinary sRGB photo turned into the RAW mosaic a given
//! camera would have recorded of the scene, so that denoisers can train on
//! natural images of any camera without clean RAWs of it.
//!
//! Each step inverts one step of pgrf's own preview pipeline
//! ([`pgrf_raw::render_preview`]), so that unprocessing and then previewing
//! gives the photo back: inverse sRGB transfer, inverse camera -> sRGB
//! matrix (from the camera's DNG colour matrix), inverse white balance
//! (division by the camera's white-balance multipliers), an exposure factor,
//! then the camera's CFA phase and black/white levels.

use crate::error::{Result, SceneError};
use crate::photo::Photo;
use pgrf_core::seed::mix64;
use pgrf_raw::color::{camera_from_srgb, srgb_decode};
use pgrf_raw::{Cfa, ColorMatrix, RawFrame};
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;

/// Range of the per-crop exposure factor of [`Unprocessing::jittered`]
/// (log-uniform).
pub const EXPOSURE: (f32, f32) = (0.5, 1.5);
/// Training's default largest factor on the red and the blue white-balance
/// multiplier (and its inverse the smallest), log-uniform: about the spread
/// of daylight, shade and flash on one camera.
pub const WB_SPREAD: f32 = 1.25;
/// Largest relative change of a colour-matrix entry.
pub const MATRIX_SPREAD: f32 = 0.1;

const COLOUR_DOMAIN: u64 = 0x636f_6c6f; // "colo"

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
    /// The Sony A7S2 of pgrf's built-in noise profile: its published D65
    /// matrix, the white balance that makes D65 neutral, RGGB, black 512,
    /// white 16383 (its 14-bit ARW).
    pub fn sony_a7s2() -> CameraSpace {
        CameraSpace {
            xyz_to_cam: crate::chart::A7S2_D65_MATRIX,
            wb: crate::chart::a7s2_daylight_wb(),
            cfa: Cfa::Rggb,
            black: [512.0; 4],
            white: 16383,
        }
    }

    /// The camera space of a decoded RAW file: its colour matrix, as-shot
    /// white balance, CFA and levels. Refused (with the reason) when the
    /// file has no colour matrix or no white balance.
    pub fn of(frame: &RawFrame) -> Result<CameraSpace> {
        let cm = frame.color_matrix().ok_or(SceneError::NoCameraSpace {
            missing: "colour matrix",
        })?;
        let wb = frame.wb.ok_or(SceneError::NoCameraSpace {
            missing: "as-shot white balance",
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

/// The parameters of one unprocessing: which colours the camera sees and
/// how bright the scene is. Training draws a different one per crop
/// (pgrf-nn's photo source) so that a network cannot learn a colour prior;
/// [`Unprocessing::plain`] is the camera's own.
#[derive(Clone, Debug, PartialEq)]
pub struct Unprocessing {
    /// White-balanced camera RGB from linear sRGB; each row sums to 1 so
    /// that sRGB white maps to camera white before the white balance.
    pub cam_from_srgb: [[f32; 3]; 3],
    /// White-balance multipliers R, G, B that the result is divided by.
    pub wb: [f32; 3],
    /// Linear-light exposure factor (1 keeps the photo's brightness).
    pub exposure: f32,
    /// Invert a global S-shaped tone curve (Brooks et al.'s smoothstep,
    /// `3x^2 - 2x^3`) before the sRGB transfer, for photos whose renderer
    /// added one.
    pub inverse_tone: bool,
}

impl Unprocessing {
    /// `camera`'s own matrix and white balance at `exposure`, no tone curve;
    /// refused when the matrix cannot be used.
    pub fn plain(camera: &CameraSpace, exposure: f32) -> Result<Unprocessing> {
        let m = camera_from_srgb(&camera.xyz_to_cam).ok_or(SceneError::UnusableMatrix)?;
        let u = Unprocessing {
            cam_from_srgb: m.map(|row| row.map(|v| v as f32)),
            wb: camera.wb,
            exposure,
            inverse_tone: false,
        };
        u.check()?;
        Ok(u)
    }

    /// Refuse parameters that would make nonsense (non-positive exposure or
    /// multipliers, non-finite matrix entries).
    pub fn check(&self) -> Result<()> {
        if !(self.exposure.is_finite() && self.exposure > 0.0) {
            return Err(SceneError::BadExposure {
                exposure: self.exposure,
            });
        }
        if self.wb.iter().any(|g| !(g.is_finite() && *g > 0.0)) {
            return Err(SceneError::BadWhiteBalance { wb: self.wb });
        }
        if self.cam_from_srgb.iter().flatten().any(|v| !v.is_finite()) {
            return Err(SceneError::NonFiniteMatrix);
        }
        Ok(())
    }

    /// This unprocessing varied as training varies it per crop, drawn from
    /// `seed` alone (repeatable, independent of the worker count):
    /// exposure log-uniform in [`EXPOSURE`]; the red and blue
    /// white-balance multipliers each scaled by a log-uniform factor in
    /// [1 / `wb_spread`, `wb_spread`]; each camera-from-sRGB matrix entry
    /// scaled by 1 + U(-[`MATRIX_SPREAD`], [`MATRIX_SPREAD`]), rows then
    /// renormalised to their former sums (white stays white before the
    /// white balance).
    pub fn jittered(&self, seed: u64, wb_spread: f32) -> Unprocessing {
        let mut u = self.clone();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(mix64(seed ^ COLOUR_DOMAIN));
        let mut log_uniform = |lo: f32, hi: f32| -> f32 {
            (lo.ln() + (hi.ln() - lo.ln()) * rng.random::<f32>()).exp()
        };
        u.exposure = log_uniform(EXPOSURE.0, EXPOSURE.1);
        u.wb[0] *= log_uniform(1.0 / wb_spread, wb_spread);
        u.wb[2] *= log_uniform(1.0 / wb_spread, wb_spread);
        for row in u.cam_from_srgb.iter_mut() {
            let sum: f32 = row.iter().sum();
            for v in row.iter_mut() {
                *v *= 1.0 + MATRIX_SPREAD * (2.0 * rng.random::<f32>() - 1.0);
            }
            let new: f32 = row.iter().sum();
            if new.abs() > 1e-6 {
                row.iter_mut().for_each(|v| *v *= sum / new);
            }
        }
        u
    }

    /// Channel `ch` (0 R, 1 G, 2 B) of the camera for linear sRGB `lin`, as
    /// a fraction of the sensor's range (not clipped).
    #[inline]
    fn camera_fraction(&self, ch: usize, lin: [f32; 3]) -> f32 {
        let m = &self.cam_from_srgb[ch];
        (m[0] * lin[0] + m[1] * lin[1] + m[2] * lin[2]) / self.wb[ch] * self.exposure
    }
}

/// Brooks et al.'s inverse of the smoothstep tone curve `3x^2 - 2x^3`.
fn inverse_smoothstep(y: f32) -> f32 {
    let y = y.clamp(0.0, 1.0);
    0.5 - ((1.0 - 2.0 * y).asin() / 3.0).sin()
}

/// The plane order R, G1, B, G2 as colour channels.
const CHANNEL_OF_PLANE: [usize; 4] = [0, 1, 2, 1];

/// Unprocess an sRGB-encoded photo into `camera`'s RAW space, scaled by
/// `exposure` (linear light; 1 keeps the photo's brightness). Values that
/// leave the sensor's range are clipped at white and at 0 DN. The result
/// carries the camera's matrix and white balance so that its preview
/// renders the photo again.
pub fn unprocess(photo: &Photo, camera: &CameraSpace, exposure: f32) -> Result<RawFrame> {
    let u = Unprocessing::plain(camera, exposure)?;
    let (rgb, width, height) = (&photo.rgb, photo.width, photo.height);
    if width < 2 || height < 2 || rgb.len() != width * height * 3 {
        return Err(SceneError::PhotoSize {
            values: rgb.len(),
            width,
            height,
        });
    }
    let mut mosaic = vec![0u16; width * height];
    mosaic
        .par_chunks_mut(width)
        .enumerate()
        .for_each(|(r, row)| {
            for (c, v) in row.iter_mut().enumerate() {
                let px = &rgb[(r * width + c) * 3..(r * width + c) * 3 + 3];
                let lin = [srgb_decode(px[0]), srgb_decode(px[1]), srgb_decode(px[2])];
                let p = camera.cfa.plane_at(r, c);
                let x = u.camera_fraction(CHANNEL_OF_PLANE[p], lin);
                let range = camera.white as f32 - camera.black[p];
                *v = (camera.black[p] + quantise(x, range) * range).round() as u16;
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

/// A fraction of the sensor's range clipped to [0, 1] and rounded to the
/// sensor's DN steps (`range` DN from black to white).
#[inline]
fn quantise(x: f32, range: f32) -> f32 {
    (x.clamp(0.0, 1.0) * range).round() / range
}

/// A photo held for cropping again and again (a training cache):
/// sRGB-encoded values as 16-bit codes, half the memory of f32 and 257
/// times finer than an 8-bit JPEG's steps.
#[derive(Clone, Debug, PartialEq)]
pub struct EncodedPhoto {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    codes: Vec<u16>,
}

impl EncodedPhoto {
    /// The photo's values as 16-bit codes.
    pub fn from_photo(p: &Photo) -> EncodedPhoto {
        EncodedPhoto {
            width: p.width,
            height: p.height,
            codes: p
                .rgb
                .iter()
                .map(|v| (v.clamp(0.0, 1.0) * 65535.0).round() as u16)
                .collect(),
        }
    }

    /// Memory held, bytes.
    pub fn bytes(&self) -> usize {
        self.codes.len() * 2
    }
}

/// Linear light of every 16-bit code, without and with the inverse tone
/// curve: a table lookup instead of a `powf` per value.
fn decode_table(inverse_tone: bool) -> &'static [f32] {
    static TABLES: std::sync::OnceLock<[Vec<f32>; 2]> = std::sync::OnceLock::new();
    let t = TABLES.get_or_init(|| {
        let make = |tone: bool| -> Vec<f32> {
            (0..=u16::MAX)
                .map(|c| {
                    let e = c as f32 / 65535.0;
                    srgb_decode(if tone { inverse_smoothstep(e) } else { e })
                })
                .collect()
        };
        [make(false), make(true)]
    });
    &t[inverse_tone as usize]
}

/// The packed clean crop `(4, patch, patch)` (planes R, G1, B, G2,
/// normalised from black to white, rounded to the camera's DN steps) of
/// the `2 * patch` square of `img` whose top-left pixel is `(y, x)`,
/// unprocessed with `u` into `camera`'s CFA and levels: what training
/// reads from a photo.
pub fn unprocess_packed(
    img: &EncodedPhoto,
    (y, x): (usize, usize),
    patch: usize,
    camera: &CameraSpace,
    u: &Unprocessing,
) -> Result<ndarray::Array3<f32>> {
    unprocess_window(img, (y, x), (patch, patch), camera, u)
}

/// [`unprocess_packed`] of any window: `(ph, pw)` packed pixels, the
/// `2 * ph` rows and `2 * pw` columns of `img` from `(y, x)`.
pub fn unprocess_window(
    img: &EncodedPhoto,
    (y, x): (usize, usize),
    (ph, pw): (usize, usize),
    camera: &CameraSpace,
    u: &Unprocessing,
) -> Result<ndarray::Array3<f32>> {
    u.check()?;
    if ph == 0 || pw == 0 || y + 2 * ph > img.height || x + 2 * pw > img.width {
        return Err(SceneError::WindowOutside {
            y,
            x,
            rows: 2 * ph,
            cols: 2 * pw,
            width: img.width,
            height: img.height,
        });
    }
    let lut = decode_table(u.inverse_tone);
    let offsets = camera.cfa.offsets();
    let mut out = ndarray::Array3::<f32>::zeros((4, ph, pw));
    for (p, &(dr, dc)) in offsets.iter().enumerate() {
        let ch = CHANNEL_OF_PLANE[p];
        let range = camera.white as f32 - camera.black[p];
        let mut plane = out.index_axis_mut(ndarray::Axis(0), p);
        plane
            .axis_iter_mut(ndarray::Axis(0))
            .into_par_iter()
            .enumerate()
            .for_each(|(py, mut row)| {
                for (px, o) in row.iter_mut().enumerate() {
                    let i = ((y + 2 * py + dr) * img.width + x + 2 * px + dc) * 3;
                    let c = &img.codes[i..i + 3];
                    let lin = [lut[c[0] as usize], lut[c[1] as usize], lut[c[2] as usize]];
                    *o = quantise(u.camera_fraction(ch, lin), range);
                }
            });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use pgrf_raw::{render_preview, PreviewOptions};

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

    /// The training path (16-bit codes, table lookups, a crop straight to
    /// packed planes) gives the full-frame path's pixels of the same window
    /// (the crop starts its own CFA phase at its corner), for every CFA
    /// phase and an odd crop position: within one DN (the codes' own
    /// rounding).
    #[test]
    fn packed_crops_match_the_full_frame() {
        let src = photo(96, 64);
        let enc = EncodedPhoto::from_photo(&src);
        assert_eq!(enc.bytes(), 96 * 64 * 3 * 2);
        for cfa in [Cfa::Rggb, Cfa::Bggr, Cfa::Grbg, Cfa::Gbrg] {
            let cam = a7s2(cfa);
            let u = Unprocessing::plain(&cam, 0.8).unwrap();
            let (y, x, patch) = (5usize, 11usize, 24usize);
            let crop = unprocess_packed(&enc, (y, x), patch, &cam, &u).unwrap();
            let side = 2 * patch;
            let window = Photo {
                width: side,
                height: side,
                rgb: (0..side)
                    .flat_map(|r| {
                        let i = ((y + r) * 96 + x) * 3;
                        src.rgb[i..i + side * 3].to_vec()
                    })
                    .collect(),
            };
            let frame = unprocess(&window, &cam, 0.8).unwrap();
            let range = 16383.0 - 512.0;
            for (p, &(dr, dc)) in cfa.offsets().iter().enumerate() {
                for py in 0..patch {
                    for px in 0..patch {
                        let (r, c) = (2 * py + dr, 2 * px + dc);
                        let want = (frame.mosaic[r * side + c] as f32 - 512.0) / range;
                        let got = crop[[p, py, px]];
                        assert!(
                            (got - want).abs() * range <= 1.001,
                            "{cfa:?} {p} {py} {px} {} {}",
                            got * range,
                            want * range
                        );
                    }
                }
            }
        }
        let cam = a7s2(Cfa::Rggb);
        let u = Unprocessing::plain(&cam, 1.0).unwrap();
        let e = unprocess_packed(&enc, (60, 0), 8, &cam, &u).unwrap_err();
        assert!(e.to_string().contains("does not fit"), "{e}");
    }

    /// The inverse tone curve undoes smoothstep, and brightens the shadows
    /// of what it is applied to (the curve darkened them).
    #[test]
    fn inverse_tone_undoes_smoothstep() {
        for i in 0..=100 {
            let x = i as f32 / 100.0;
            let y = 3.0 * x * x - 2.0 * x * x * x;
            assert!((inverse_smoothstep(y) - x).abs() < 1e-4, "{x}");
        }
        assert!(inverse_smoothstep(0.2) > 0.2 && inverse_smoothstep(0.8) < 0.8);
    }
}
