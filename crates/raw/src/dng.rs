//! Writing a `RawFrame` as a DNG with rawler's writer.
//!
//! The DNG is what pgrf hands back to the photographer's raw converter, so it
//! must be a faithful container: same mosaic size and CFA phase, same per-plane
//! black and white levels, colour matrix, as-shot neutral, ISO, exposure and
//! camera names. Pixels are LJPEG-92 lossless by default.

use crate::error::{RawError, Result};
use crate::frame::{ColorMatrix, RawFrame};
use crate::panic_guard::quietly;
use pgrf_core::write_atomic;
use rawler::cfa::{PlaneColor, CFA};
use rawler::decoders::{Camera, RawMetadata};
use rawler::dng::writer::DngWriter;
use rawler::dng::{CropMode, DngCompression, DngPhotometricConversion, DNG_VERSION_V1_4};
use rawler::formats::tiff::{Rational, SRational};
use rawler::imgop::xyz::Illuminant;
use rawler::pixarray::PixU16;
use rawler::rawimage::{BlackLevel, CFAConfig, RawImage, RawPhotometricInterpretation, WhiteLevel};
use rawler::tags::{DngTag, ExifTag, TiffCommonTag};
use std::io::Cursor;
use std::path::Path;

/// Pixel compression inside the DNG.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Compression {
    /// LJPEG-92, what Adobe's converter writes; about half the size.
    #[default]
    Lossless,
    /// Plain 16-bit samples: larger, readable by any TIFF reader.
    Uncompressed,
}

/// How [`write_dng`] and [`encode_dng`] write a frame; the default is
/// lossless LJPEG-92 with pgrf's version in the Software tag.
#[derive(Clone, Debug)]
pub struct DngOptions {
    /// Pixel compression.
    pub compression: Compression,
    /// Written to the Software tag.
    pub software: String,
}

impl Default for DngOptions {
    fn default() -> Self {
        DngOptions {
            compression: Compression::Lossless,
            software: format!("pgrf {}", env!("CARGO_PKG_VERSION")),
        }
    }
}

/// Encode `frame` as DNG bytes.
pub fn encode_dng(frame: &RawFrame, opts: &DngOptions) -> Result<Vec<u8>> {
    frame.check_levels()?;
    if frame.mosaic.len() != frame.width * frame.height {
        return Err(RawError::MosaicInconsistent);
    }
    if frame.width > u16::MAX as usize || frame.height > u16::MAX as usize {
        return Err(RawError::TooLargeForDng {
            width: frame.width,
            height: frame.height,
        });
    }
    let image = rawler_image(frame);
    let exif = exif_for(frame);
    quietly(|| -> std::result::Result<Vec<u8>, String> {
        let mut buf = Cursor::new(Vec::with_capacity(frame.mosaic.len() * 2 + 65536));
        let mut dng = DngWriter::new(&mut buf, DNG_VERSION_V1_4).map_err(|e| e.to_string())?;
        let mut raw = dng.subframe_on_root(0);
        let compression = match opts.compression {
            Compression::Lossless => DngCompression::Lossless,
            Compression::Uncompressed => DngCompression::Uncompressed,
        };
        raw.raw_image(
            &image,
            CropMode::None,
            compression,
            DngPhotometricConversion::Original,
            1,
        )
        .map_err(|e| e.to_string())?;
        if let Some(np) = &frame.noise_profile {
            let flat: Vec<f64> = np.iter().flatten().copied().collect();
            raw.ifd_mut()
                .add_tag(rawler::tags::DngTag::NoiseProfile, flat.as_slice());
        }
        raw.finalize().map_err(|e| e.to_string())?;
        dng.load_base_tags(&image).map_err(|e| e.to_string())?;
        dng.load_metadata(&exif).map_err(|e| e.to_string())?;
        write_color_tags(&mut dng, frame);
        if let Some(t) = frame.temperature_c.filter(|t| t.is_finite()) {
            dng.exif_ifd_mut().add_tag(
                ExifTag::AmbientTemperature,
                SRational::new((t as f64 * 100.0).round() as i32, 100),
            );
        }
        let root = dng.root_ifd_mut();
        root.add_tag(ExifTag::Orientation, frame.orientation);
        root.add_tag(TiffCommonTag::Software, opts.software.as_str());
        dng.close().map_err(|e| e.to_string())?;
        Ok(buf.into_inner())
    })
    .and_then(|r| r)
    .map_err(|reason| RawError::Encode {
        format: "DNG",
        reason,
    })
}

/// Encode `frame` as DNG (same pixels, CFA, levels, colour matrices, white
/// balance and EXIF) and write it to `path` atomically.
pub fn write_dng(frame: &RawFrame, path: &Path, opts: &DngOptions) -> Result<()> {
    let bytes = encode_dng(frame, opts)?;
    Ok(write_atomic(path, &bytes)?)
}

fn rawler_image(frame: &RawFrame) -> RawImage {
    let mut cam = Camera::new();
    cam.make = frame.make.clone();
    cam.model = frame.model.clone();
    cam.clean_make = frame.make.clone();
    cam.clean_model = frame.model.clone();
    cam.cfa = CFA::new(frame.cfa.name());
    cam.plane_color = PlaneColor::new("RGB");
    cam.real_bps = frame.bits.clamp(1, 16) as usize;
    // Black level as a 2x2 repeat pattern anchored at pixel (0, 0).
    let pattern: Vec<Rational> = (0..2)
        .flat_map(|r| (0..2).map(move |c| (r, c)))
        .map(|(r, c)| rational_level(frame.black[frame.cfa.plane_at(r, c)]))
        .collect();
    let black = BlackLevel {
        levels: pattern,
        cpp: 1,
        width: 2,
        height: 2,
    };
    let white = WhiteLevel::new(vec![frame.white]);
    // A monochrome frame is a one-sample LinearRaw image: how the DNG
    // specification and Leica's Monochrom DNGs store a sensor without a
    // colour filter. Its black pattern still repeats 2x2.
    let photometric = if frame.mono {
        RawPhotometricInterpretation::LinearRaw
    } else {
        RawPhotometricInterpretation::Cfa(CFAConfig::new(&cam.cfa, &cam.plane_color))
    };
    // The writer derives AsShotNeutral from these; it is rewritten exactly below.
    let wb = frame
        .wb
        .map(|w| [w[0], w[1], w[2], f32::NAN])
        .unwrap_or([1.0, 1.0, 1.0, f32::NAN]);
    let pixels = PixU16::new_with(frame.mosaic.clone(), frame.width, frame.height);
    RawImage::new(
        cam,
        pixels,
        1,
        wb,
        photometric,
        Some(black),
        Some(white),
        false,
    )
}

/// Integer levels stay integers (most readers expect SHORT/LONG); fractional
/// ones are written as rationals with 1/1000 DN resolution.
fn rational_level(v: f32) -> Rational {
    if v.fract() == 0.0 {
        Rational::new(v as u32, 1)
    } else {
        Rational::new((v * 1000.0).round() as u32, 1000)
    }
}

fn write_color_tags<B: std::io::Write + std::io::Seek>(dng: &mut DngWriter<B>, frame: &RawFrame) {
    let root = dng.root_ifd_mut();
    if frame.mono {
        // No colour: no neutral, no matrices (readers then show grey).
        root.remove_tag(DngTag::AsShotNeutral);
        return;
    }
    match frame.wb {
        Some(w) => {
            // AsShotNeutral is the camera response to neutral: reciprocal multipliers.
            let neutral: Vec<Rational> = w.iter().map(|m| ratio_u(1.0 / *m as f64)).collect();
            root.add_tag(DngTag::AsShotNeutral, neutral.as_slice());
        }
        None => root.remove_tag(DngTag::AsShotNeutral),
    }
    // DNG has two matrix slots; with more than two, keep the warmest
    // illuminant and the daylight one (the pair converters interpolate).
    let slots: Vec<&ColorMatrix> = match frame.color_matrices.as_slice() {
        [] => vec![],
        [one] => vec![one],
        [first, .., last] => vec![first, last],
    };
    for (slot, cm) in slots.into_iter().enumerate() {
        let illum = illuminant_from_name(&cm.illuminant).unwrap_or(Illuminant::Unknown);
        // rawler's own conversion truncates to 1/10000; round instead so
        // matrices read from a DNG are written back bit for bit.
        let m: Vec<SRational> = cm
            .xyz_to_cam
            .iter()
            .flatten()
            .map(|v| SRational::new((*v as f64 * 10000.0).round() as i32, 10000))
            .collect();
        dng.color_matrix(slot + 1, illum, m.as_slice());
    }
}

fn ratio_u(v: f64) -> Rational {
    let d = 1_000_000u32;
    Rational::new((v * d as f64).round().max(0.0) as u32, d)
}

fn illuminant_from_name(name: &str) -> Option<Illuminant> {
    (0u16..=255)
        .filter_map(|c| Illuminant::try_from(c).ok())
        .find(|i| format!("{i:?}") == name)
}

/// EXIF for the DNG: the source file's record when there is one, with ISO and
/// exposure taken from the frame (they may have been edited, e.g. by synthesis).
fn exif_for(frame: &RawFrame) -> RawMetadata {
    let mut m = frame.exif.clone().unwrap_or_default();
    m.exif.orientation = Some(frame.orientation);
    m.make = frame.make.clone();
    m.model = frame.model.clone();
    match frame.iso {
        Some(iso) => {
            m.exif.iso_speed_ratings = u16::try_from(iso).ok();
            m.exif.iso_speed = Some(iso);
        }
        None => {
            m.exif.iso_speed_ratings = None;
            m.exif.iso_speed = None;
        }
    }
    m.exif.exposure_time = frame
        .exposure_s
        .filter(|t| *t > 0.0 && t.is_finite())
        .map(exposure_rational);
    m
}

/// Exposure as EXIF writes it: 1/N for short exposures, N/10 style otherwise,
/// so 1/60 s stays exactly 1/60.
fn exposure_rational(t: f64) -> Rational {
    if t < 1.0 {
        let inv = 1.0 / t;
        if (inv - inv.round()).abs() < 1e-6 * inv {
            return Rational::new(1, inv.round() as u32);
        }
    }
    let d = if t < 4000.0 { 1_000_000u32 } else { 1 };
    Rational::new((t * d as f64).round() as u32, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The capture temperature survives a DNG round trip (EXIF
    /// AmbientTemperature, to 0.01 degree), and a frame without one stays
    /// without.
    #[test]
    fn temperature_round_trips() {
        let mut f = RawFrame::from_mosaic(8, 6, vec![600; 48], crate::Cfa::Rggb, [512.0; 4], 16383)
            .unwrap();
        let back = |f: &RawFrame| {
            let bytes = encode_dng(f, &DngOptions::default()).unwrap();
            crate::decode_bytes(std::path::Path::new("t.dng"), &bytes, &Default::default())
                .unwrap()
                .temperature_c
        };
        assert_eq!(back(&f), None);
        f.temperature_c = Some(-10.25);
        assert_eq!(back(&f), Some(-10.25));
        f.temperature_c = Some(23.0);
        assert_eq!(back(&f), Some(23.0));
    }

    #[test]
    fn exposure_rationals() {
        let r = exposure_rational(1.0 / 60.0);
        assert_eq!((r.n, r.d), (1, 60));
        let r = exposure_rational(0.1);
        assert_eq!((r.n, r.d), (1, 10));
        let r = exposure_rational(2.5);
        assert!((r.n as f64 / r.d as f64 - 2.5).abs() < 1e-9);
        let r = exposure_rational(0.0123);
        assert!((r.n as f64 / r.d as f64 - 0.0123).abs() < 1e-9);
    }

    #[test]
    fn illuminant_names_round_trip() {
        assert_eq!(illuminant_from_name("D65"), Some(Illuminant::D65));
        assert_eq!(illuminant_from_name("A"), Some(Illuminant::A));
        assert_eq!(illuminant_from_name("nope"), None);
    }
}
