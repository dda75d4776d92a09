//! sRGB previews of a raw frame, for looking at inputs and results.
//!
//! Pipeline, in the order a raw converter applies it: per-plane black/white
//! normalisation, camera white balance and exposure gain on the mosaic,
//! highlight clipping at the sensor's saturation (so clipped highlights stay
//! neutral instead of turning pink), demosaic, camera->sRGB matrix, sRGB curve.

use crate::color::{srgb_encode, srgb_from_camera, Mat3, IDENTITY};
use crate::demosaic::{demosaic, Demosaic};
use crate::error::{RawError, Result};
use crate::frame::RawFrame;
use crate::orientation::apply_orientation;
use pgrf_core::write_atomic;
use rayon::prelude::*;
use std::path::Path;

/// How [`render_preview`] turns a mosaic into sRGB; the default is gain 1,
/// Malvar demosaic, full size, as-shot white balance, upright orientation.
#[derive(Clone, Debug)]
pub struct PreviewOptions {
    /// Linear exposure multiplier applied before clipping (x100 to look at a
    /// frame shot 100x too dark).
    pub gain: f32,
    /// Demosaic method for full-size previews (unused with `half`).
    pub demosaic: Demosaic,
    /// Half size: one output pixel per 2x2 cell, no interpolation. Four times
    /// fewer pixels, no demosaic artefacts; what you want for big batches.
    pub half: bool,
    /// Ignore the file's white balance (multipliers of 1).
    pub no_wb: bool,
    /// Show pixels in sensor order instead of turning the picture upright
    /// by the file's EXIF orientation.
    pub keep_orientation: bool,
}

impl Default for PreviewOptions {
    fn default() -> Self {
        PreviewOptions {
            gain: 1.0,
            demosaic: Demosaic::Malvar,
            half: false,
            no_wb: false,
            keep_orientation: false,
        }
    }
}

/// A rendered preview: linear-light-free, sRGB-encoded RGB in [0, 1].
#[derive(Clone, Debug)]
pub struct Preview {
    /// Width in pixels, after orientation (and halving).
    pub width: usize,
    /// Height in pixels, after orientation (and halving).
    pub height: usize,
    /// Interleaved sRGB-encoded values in [0, 1].
    pub rgb: Vec<f32>,
    /// Set when the file had no usable colour matrix and identity was used.
    pub warnings: Vec<String>,
}

/// Render `frame` to sRGB: black/white normalisation, white balance,
/// exposure gain, highlight clipping, demosaic (or 2x2 binning with `half`),
/// camera -> sRGB matrix, sRGB curve, EXIF orientation.
pub fn render_preview(frame: &RawFrame, opts: &PreviewOptions) -> Result<Preview> {
    if !opts.gain.is_finite() || opts.gain <= 0.0 {
        return Err(RawError::BadGain { gain: opts.gain });
    }
    frame.check_levels()?;
    if frame.mono {
        return Ok(render_mono(frame, opts));
    }
    let mut warnings = Vec::new();
    let (wb, matrix) = colour_of(frame, opts, &mut warnings);

    // Normalised, balanced, amplified and clipped mosaic.
    let scale: [f32; 4] = std::array::from_fn(|p| 1.0 / (frame.white as f32 - frame.black[p]));
    let plane_gain: [f32; 4] = [wb[0], wb[1], wb[2], wb[1]].map(|g| g * opts.gain);
    let w = frame.width;
    let cfa = frame.cfa;
    let mut lin = vec![0.0f32; frame.mosaic.len()];
    lin.par_chunks_mut(w).enumerate().for_each(|(r, row)| {
        let src = &frame.mosaic[r * w..(r + 1) * w];
        for (c, v) in row.iter_mut().enumerate() {
            let p = cfa.plane_at(r, c);
            let x = (src[c] as f32 - frame.black[p]) * scale[p];
            *v = (x * plane_gain[p]).clamp(0.0, 1.0);
        }
    });

    let (width, height, mut rgb) = if opts.half {
        binned(frame, &lin)
    } else {
        (
            w,
            frame.height,
            demosaic(&lin, w, frame.height, cfa, opts.demosaic),
        )
    };

    let m: [[f32; 3]; 3] = to_f32(&matrix);
    rgb.par_chunks_mut(3).for_each(|p| {
        let (r, g, b) = (p[0], p[1], p[2]);
        for k in 0..3 {
            p[k] = srgb_encode(m[k][0] * r + m[k][1] * g + m[k][2] * b);
        }
    });
    let (rgb, width, height) = if opts.keep_orientation {
        (rgb, width, height)
    } else {
        apply_orientation(&rgb, width, height, 3, frame.orientation)
    };
    Ok(Preview {
        width,
        height,
        rgb,
        warnings,
    })
}

/// The white balance and the camera -> sRGB matrix the preview uses, with
/// a warning for each the file lacks (multipliers of 1, identity).
fn colour_of(
    frame: &RawFrame,
    opts: &PreviewOptions,
    warnings: &mut Vec<String>,
) -> ([f32; 3], [[f64; 3]; 3]) {
    let wb = match (opts.no_wb, frame.wb) {
        (true, _) => [1.0; 3],
        (false, Some(wb)) => wb,
        (false, None) => {
            warnings
                .push("no as-shot white balance in the file: using multipliers of 1".to_string());
            [1.0; 3]
        }
    };
    let matrix = match frame
        .color_matrix()
        .and_then(|cm| srgb_from_camera(&cm.xyz_to_cam))
    {
        Some(m) => m,
        None => {
            warnings.push(
                "no usable colour matrix in the file: camera RGB shown as sRGB (identity)"
                    .to_string(),
            );
            IDENTITY
        }
    };
    (wb, matrix)
}

/// The mosaic `lin` binned 2x2 into RGB (the greens averaged): (width,
/// height, pixels).
fn binned(frame: &RawFrame, lin: &[f32]) -> (usize, usize, Vec<f32>) {
    let w = frame.width;
    let (ph, pw) = frame.packed_dims();
    let off = frame.cfa.offsets();
    let mut rgb = vec![0.0f32; ph * pw * 3];
    rgb.par_chunks_mut(pw * 3).enumerate().for_each(|(i, row)| {
        for j in 0..pw {
            let at = |p: usize| lin[(2 * i + off[p].0) * w + 2 * j + off[p].1];
            row[j * 3] = at(0);
            row[j * 3 + 1] = 0.5 * (at(1) + at(3));
            row[j * 3 + 2] = at(2);
        }
    });
    (pw, ph, rgb)
}

/// A monochrome frame in grey: normalisation, gain, clipping, sRGB curve
/// (no white balance, matrix or demosaic: there is one colour); `half`
/// averages each 2x2 cell.
fn render_mono(frame: &RawFrame, opts: &PreviewOptions) -> Preview {
    let (w, h) = (frame.width, frame.height);
    let value = |r: usize, c: usize| {
        let p = frame.cfa.plane_at(r, c);
        let x = (frame.at(r, c) as f32 - frame.black[p]) / (frame.white as f32 - frame.black[p]);
        (x * opts.gain).clamp(0.0, 1.0)
    };
    let (width, height) = if opts.half { (w / 2, h / 2) } else { (w, h) };
    let mut rgb = vec![0.0f32; width * height * 3];
    rgb.par_chunks_mut(width * 3)
        .enumerate()
        .for_each(|(i, row)| {
            for j in 0..width {
                let v = if opts.half {
                    0.25 * (value(2 * i, 2 * j)
                        + value(2 * i, 2 * j + 1)
                        + value(2 * i + 1, 2 * j)
                        + value(2 * i + 1, 2 * j + 1))
                } else {
                    value(i, j)
                };
                row[j * 3..j * 3 + 3].fill(srgb_encode(v));
            }
        });
    let (rgb, width, height) = if opts.keep_orientation {
        (rgb, width, height)
    } else {
        apply_orientation(&rgb, width, height, 3, frame.orientation)
    };
    Preview {
        width,
        height,
        rgb,
        warnings: Vec::new(),
    }
}

fn to_f32(m: &Mat3) -> [[f32; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| m[i][j] as f32))
}

impl Preview {
    /// Encode as PNG, 8 or 16 bits per channel.
    pub(crate) fn encode_png(&self, bits: u8) -> Result<Vec<u8>> {
        use image::ImageEncoder;
        let mut out = Vec::new();
        let enc = image::codecs::png::PngEncoder::new(&mut out);
        let (w, h) = (self.width as u32, self.height as u32);
        let res = match bits {
            8 => {
                let buf: Vec<u8> = self.rgb.iter().map(|v| (v * 255.0).round() as u8).collect();
                enc.write_image(&buf, w, h, image::ExtendedColorType::Rgb8)
            }
            16 => {
                // The encoder takes native-endian samples and writes PNG's big-endian.
                let buf: Vec<u8> = self
                    .rgb
                    .iter()
                    .flat_map(|v| ((v * 65535.0).round() as u16).to_ne_bytes())
                    .collect();
                enc.write_image(&buf, w, h, image::ExtendedColorType::Rgb16)
            }
            b => return Err(RawError::PngBits { bits: b }),
        };
        res.map_err(|e| RawError::Encode {
            format: "PNG",
            reason: e.to_string(),
        })?;
        Ok(out)
    }

    /// Encode as PNG with `bits` (8 or 16) per channel and write it to
    /// `path` atomically.
    pub fn write_png(&self, path: &Path, bits: u8) -> Result<()> {
        Ok(write_atomic(path, &self.encode_png(bits)?)?)
    }
}

/// The size (width, height) of the PNG at `path`, every pixel decoded: an
/// error when it is not a whole PNG (cut short by a killed copy, damaged),
/// so that `pgrf enhance --skip-existing` keeps a preview only when it
/// reads back whole.
pub fn png_size(path: &Path) -> Result<(usize, usize)> {
    // The closing IEND chunk (empty, fixed CRC): decoders stop after the
    // pixels and would not notice a file cut short within it.
    const IEND: [u8; 12] = [0, 0, 0, 0, b'I', b'E', b'N', b'D', 0xAE, 0x42, 0x60, 0x82];
    let bytes = std::fs::read(path).map_err(|e| RawError::io(path, e))?;
    if !bytes.ends_with(&IEND) {
        return Err(RawError::decode(
            path,
            "not a whole PNG (no IEND chunk at its end)",
        ));
    }
    let image = image::load_from_memory_with_format(&bytes, image::ImageFormat::Png)
        .map_err(|e| RawError::decode(path, e.to_string()))?;
    Ok((image.width() as usize, image.height() as usize))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cfa::Cfa;
    use crate::frame::ColorMatrix;

    /// A frame whose camera values are a neutral grey under the given white balance.
    fn grey_frame(cfa: Cfa, level: f32) -> RawFrame {
        let wb = [2.0f32, 1.0, 1.5];
        let (w, h) = (16, 12);
        let mosaic = (0..w * h)
            .map(|i| {
                let c = cfa.color_at(i / w, i % w);
                (512.0 + level / wb[c] * (16383.0 - 512.0)).round() as u16
            })
            .collect();
        let mut f = RawFrame::from_mosaic(w, h, mosaic, cfa, [512.0; 4], 16383).unwrap();
        f.wb = Some(wb);
        f.color_matrices = vec![ColorMatrix {
            xyz_to_cam: [
                [0.6461, -0.1164, -0.0857],
                [-0.3825, 1.1597, 0.2534],
                [-0.0416, 0.154, 0.6039],
            ],
            illuminant: "D65".into(),
        }];
        f
    }

    #[test]
    fn neutral_grey_renders_grey_at_the_right_level() {
        for cfa in Cfa::ALL {
            for half in [false, true] {
                let f = grey_frame(cfa, 0.18);
                let p = render_preview(
                    &f,
                    &PreviewOptions {
                        half,
                        ..Default::default()
                    },
                )
                .unwrap();
                assert!(p.warnings.is_empty());
                for px in p.rgb.chunks(3) {
                    for v in px {
                        // 18% grey -> 0.4614 encoded; u16 rounding of the mosaic costs < 1e-3.
                        assert!((v - 0.4614).abs() < 2e-3, "{cfa} half={half}: {px:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn gain_and_highlight_clipping() {
        let f = grey_frame(Cfa::Rggb, 0.18);
        let p = render_preview(
            &f,
            &PreviewOptions {
                gain: 10.0,
                ..Default::default()
            },
        )
        .unwrap();
        // 1.8 clips to white on every channel: still neutral, not pink.
        assert!(p.rgb.iter().all(|v| (v - 1.0).abs() < 1e-5));
        assert!(render_preview(
            &f,
            &PreviewOptions {
                gain: 0.0,
                ..Default::default()
            }
        )
        .is_err());
        assert!(render_preview(
            &f,
            &PreviewOptions {
                gain: f32::NAN,
                ..Default::default()
            }
        )
        .is_err());
    }

    #[test]
    fn exif_orientation_turns_the_preview_upright() {
        let mut f = grey_frame(Cfa::Rggb, 0.18);
        f.orientation = 6;
        let p = render_preview(&f, &PreviewOptions::default()).unwrap();
        assert_eq!((p.width, p.height), (12, 16));
        let keep = PreviewOptions {
            keep_orientation: true,
            ..Default::default()
        };
        let p = render_preview(&f, &keep).unwrap();
        assert_eq!((p.width, p.height), (16, 12));
    }

    #[test]
    fn missing_matrix_warns_and_uses_identity() {
        let mut f = grey_frame(Cfa::Bggr, 0.18);
        f.color_matrices.clear();
        let p = render_preview(&f, &PreviewOptions::default()).unwrap();
        assert_eq!(p.warnings.len(), 1);
        assert!((p.rgb[0] - 0.4614).abs() < 2e-3);
    }

    #[test]
    fn png_round_trip_8_and_16_bit() {
        let f = grey_frame(Cfa::Grbg, 0.18);
        let p = render_preview(&f, &PreviewOptions::default()).unwrap();
        for bits in [8u8, 16] {
            let bytes = p.encode_png(bits).unwrap();
            let img = image::load_from_memory(&bytes).unwrap();
            assert_eq!((img.width(), img.height()), (16, 12));
            let px = img.to_rgb16().get_pixel(3, 3).0;
            let want = (p.rgb[(3 * 16 + 3) * 3] * 65535.0) as f32;
            let tol = if bits == 8 { 257.0 } else { 1.0 };
            assert!(
                (px[0] as f32 - want).abs() <= tol,
                "{bits}: {px:?} vs {want}"
            );
        }
        assert!(p.encode_png(12).is_err());
    }

    /// A whole PNG gives its size; one cut short anywhere, or not a PNG,
    /// is an error naming the file.
    #[test]
    fn png_size_reads_only_whole_pngs() {
        let d = std::env::temp_dir().join(format!("pgrf-png-size-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let path = d.join("p.png");
        let p = render_preview(&grey_frame(Cfa::Rggb, 0.18), &PreviewOptions::default()).unwrap();
        let bytes = p.encode_png(8).unwrap();
        std::fs::write(&path, &bytes).unwrap();
        assert_eq!(png_size(&path).unwrap(), (16, 12));
        for keep in [0, 8, bytes.len() / 2, bytes.len() - 1] {
            std::fs::write(&path, &bytes[..keep]).unwrap();
            let e = png_size(&path).unwrap_err().to_string();
            assert!(e.contains("p.png"), "{keep}: {e}");
        }
        std::fs::remove_dir_all(&d).unwrap();
    }
}
