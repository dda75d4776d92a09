//! Decoding camera RAW files (ARW, NEF, CR2, CR3, RAF, DNG, ...) through rawler
//! into a `RawFrame`.
//!
//! Only what pgrf's physics needs is kept: the visible Bayer (or monochrome)
//! mosaic as u16, its levels, white balance, colour matrix and exposure
//! metadata. Files that are not sensor mosaics (X-Trans, Foveon,
//! linear/demosaiced DNGs, float DNGs) are refused with a reason rather than
//! half-handled.

use crate::cfa::Cfa;
use crate::error::{RawError, Result};
use crate::frame::{bits_for, ColorMatrix, LevelOverrides, RawFrame};
use crate::masked::{Area, Masked, MaskedSource, MaskedStrip};
use crate::panic_guard::quietly;
use rawler::decoders::{RawDecodeParams, RawMetadata};
use rawler::imgop::xyz::Illuminant;
use rawler::rawimage::{CFAConfig, RawImage, RawImageData, RawPhotometricInterpretation};
use rawler::rawsource::RawSource;
use std::path::Path;

/// Decode a camera RAW file (ARW, NEF, CR2, CR3, RAF, DNG, ... through
/// rawler; FITS through [`crate::fits`]) into its visible Bayer mosaic with levels, white balance, colour
/// matrices and EXIF, then apply `overrides` to the levels. Monochrome files
/// come back with [`RawFrame::mono`] set. Files that are not integer sensor
/// mosaics (X-Trans, linear or float DNGs) are refused with
/// [`RawError::Unsupported`].
pub fn decode_file(path: &Path, overrides: &LevelOverrides) -> Result<RawFrame> {
    let meta = std::fs::metadata(path).map_err(|e| RawError::io(path, e))?;
    if meta.is_dir() {
        return Err(RawError::unsupported(
            path,
            "is a directory, expected a RAW file",
        ));
    }
    if meta.len() == 0 {
        return Err(RawError::decode(path, "file is empty"));
    }
    decode_source(path, || RawSource::new(path), overrides)
}

/// The sensor temperature a RAW or FITS file records (EXIF
/// AmbientTemperature of a TIFF-based RAW, CCD-TEMP of a FITS header), read
/// from its metadata without decoding a pixel: what [`decode_file`] puts in
/// [`RawFrame::temperature_c`]. The file is checked as `decode_file` checks
/// it before anything is read from it.
pub fn read_temperature(path: &Path) -> Result<Option<f32>> {
    let bytes = std::fs::read(path).map_err(|e| RawError::io(path, e))?;
    if bytes.is_empty() {
        return Err(RawError::decode(path, "file is empty"));
    }
    if crate::fits::is_fits(&bytes) {
        return crate::fits::fits_temperature(path, &bytes);
    }
    crate::container::check(&bytes).map_err(|source| RawError::Container {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(crate::container::exif_temperature(&bytes))
}

/// [`decode_file`] for a file already in memory (e.g. one built into the
/// binary); `name` stands for it in messages.
pub fn decode_bytes(name: &Path, bytes: &[u8], overrides: &LevelOverrides) -> Result<RawFrame> {
    if bytes.is_empty() {
        return Err(RawError::decode(name, "file is empty"));
    }
    decode_source(name, || Ok(RawSource::new_from_slice(bytes)), overrides)
}

/// Decode what `open` gives through rawler; `path` names it in errors.
fn decode_source(
    path: &Path,
    open: impl FnOnce() -> std::io::Result<RawSource>,
    overrides: &LevelOverrides,
) -> Result<RawFrame> {
    let source = open().map_err(|e| RawError::decode(path, e.to_string()))?;
    if crate::fits::is_fits(source.buf()) {
        return crate::fits_frame::frame_from_fits(path, source.buf(), overrides);
    }
    crate::container::check(source.buf()).map_err(|source| RawError::Container {
        path: path.to_path_buf(),
        source,
    })?;
    let (image, exif) = quietly(|| -> std::result::Result<_, Stop> {
        let decoder = rawler::get_decoder(&source).map_err(|e| Stop::Decoder(e.to_string()))?;
        let params = RawDecodeParams::default();
        // The frame's size without its pixels (rawler's `dummy` decode),
        // checked against the memory there is before the real decode.
        if let Ok(shape) = decoder.raw_image(&source, &params, true) {
            let (w, h) = (shape.width * shape.cpp, shape.height);
            crate::memory::check_frame(path, "decoding", w, h, crate::memory::DECODE)
                .map_err(Stop::Memory)?;
        }
        let image = decoder
            .raw_image(&source, &params, false)
            .map_err(|e| Stop::Decoder(e.to_string()))?;
        // EXIF is a convenience; a file whose pixels decode but whose
        // metadata does not is still usable.
        let exif = decoder.raw_metadata(&source, &params).ok();
        Ok((image, exif))
    })
    .map_err(|panic| RawError::decode(path, tidy_reason(&panic.to_string())))?
    .map_err(|stop| match stop {
        Stop::Decoder(reason) => RawError::decode(path, tidy_reason(&reason)),
        Stop::Memory(e) => e,
    })?;
    let masked = crate::container::masked_areas(source.buf());
    let mut frame = frame_from_rawler(path, image, exif, &masked)?;
    frame.temperature_c = crate::container::exif_temperature(source.buf());
    // A damaged NoiseProfile does not make the photo unreadable: it is left
    // out here, and `--profile dng:FILE` reports it.
    let planes = if frame.mono { 1 } else { 3 };
    frame.noise_profile = crate::container::noise_profile(source.buf(), planes)
        .ok()
        .flatten();
    frame.apply_overrides(overrides)?;
    Ok(frame)
}

/// Why a decode stopped: rawler's complaint, or a frame the memory cannot
/// hold.
enum Stop {
    Decoder(String),
    Memory(RawError),
}

/// rawler's messages start with "Error: " or carry its issue-tracker hint;
/// keep the informative part.
fn tidy_reason(reason: &str) -> String {
    let r = reason.trim_start_matches("Error: ");
    if r.starts_with("No decoder found") {
        return "not a camera RAW format rawler recognises (for a headerless sensor dump give its geometry: --width, --height, --bits, --cfa, --black)".to_string();
    }
    r.split(" Please open an issue")
        .next()
        .unwrap_or(r)
        .to_string()
}

/// The frame of rawler's decode; `dng_masked` are the DNG's MaskedAreas
/// (rawler keeps only a camera's own masked border, in `blackareas`).
fn frame_from_rawler(
    path: &Path,
    mut image: RawImage,
    exif: Option<RawMetadata>,
    dng_masked: &[Area],
) -> Result<RawFrame> {
    let config = mosaic_layout(path, &image)?;
    let (x0, y0, w, h) = visible_area(path, &image)?;
    let cfa = match &config {
        Some(config) => bayer_phase(path, config, y0, x0)?,
        // The packed planes of a monochrome frame are its sub-lattices in
        // RGGB order (RawFrame::cfa).
        None => Cfa::Rggb,
    };

    let black = black_per_plane(path, &image, cfa, y0, x0)?;
    let white = *image
        .whitelevel
        .0
        .first()
        .ok_or_else(|| RawError::decode(path, "no white level"))?;
    let masked = masked_of(&image, dng_masked, (y0, x0, h, w), cfa);
    let mosaic = visible_mosaic(&mut image, (x0, y0, w, h));

    let wb = {
        let c = image.wb_coeffs;
        let ok = c[..3].iter().all(|v| v.is_finite() && *v > 0.0);
        ok.then(|| [c[0] / c[1], 1.0, c[2] / c[1]])
    };

    let (iso, exposure_s) = exif.as_ref().map(exposure_of).unwrap_or((None, None));
    let orientation = exif
        .as_ref()
        .and_then(|m| m.exif.orientation)
        .filter(|o| (1..=8).contains(o))
        .unwrap_or(1);

    // Decoders disagree on bps (container vs sensor depth); the white level is
    // what the data actually spans.
    let bits = bits_for(white);

    let frame = RawFrame {
        width: w,
        height: h,
        mosaic,
        cfa,
        mono: config.is_none(),
        black,
        white,
        bits,
        wb: if config.is_none() { None } else { wb },
        color_matrices: color_matrices(&image),
        iso,
        exposure_s,
        make: image.clean_make.clone(),
        model: image.clean_model.clone(),
        orientation,
        sensor_origin: (y0, x0),
        sensor_size: (image.height, image.width),
        temperature_c: None,
        noise_profile: None,
        masked,
        fits: None,
        exif,
    };
    frame.check_levels().map_err(|e| {
        RawError::decode(path, format!("file metadata gives unusable levels ({e})"))
    })?;
    Ok(frame)
}

/// The black level of the readout's masked pixels ([`crate::masked`]):
/// the DNG's MaskedAreas, else rawler's camera data; the pixels kept too
/// when they are one strip of even width directly left of the visible
/// area `(y0, x0, h, w)`, its full height.
fn masked_of(
    image: &RawImage,
    dng: &[Area],
    visible: (usize, usize, usize, usize),
    cfa: Cfa,
) -> Option<Masked> {
    let RawImageData::Integer(data) = &image.data else {
        return None;
    };
    let camera: Vec<Area> = image
        .blackareas
        .iter()
        .map(|r| Area {
            top: r.p.y,
            left: r.p.x,
            bottom: r.p.y + r.d.h,
            right: r.p.x + r.d.w,
        })
        .collect();
    let (areas, source) = if dng.is_empty() {
        (camera.as_slice(), MaskedSource::Camera)
    } else {
        (dng, MaskedSource::DngTag)
    };
    let size = (image.height, image.width);
    let (level, pixels) = crate::masked::measure(data, size, areas, visible, cfa.offsets())?;
    let (y0, x0, h, _) = visible;
    let strip = match areas {
        [a] if a.right == x0 && a.top == y0 && a.bottom == y0 + h && (x0 - a.left) % 2 == 0 => {
            let columns = x0 - a.left;
            let values = (y0..y0 + h)
                .flat_map(|r| {
                    data[r * image.width + a.left..r * image.width + x0]
                        .iter()
                        .copied()
                })
                .collect();
            Some(MaskedStrip { columns, values })
        }
        _ => None,
    };
    Some(Masked {
        level,
        pixels,
        source,
        strip,
    })
}

/// The decoded image's CFA configuration, None for a monochrome mosaic,
/// after checking that it is a one-sample integer mosaic of the size it
/// claims. A monochrome file (one-sample LinearRaw DNG: Leica Monochrom,
/// pgrf's own mono DNGs; or BlackIsZero) has no CFA; its mosaic is read all
/// the same. Three-sample linear data is already demosaiced.
fn mosaic_layout(path: &Path, image: &RawImage) -> Result<Option<CFAConfig>> {
    let config = match &image.photometric {
        RawPhotometricInterpretation::Cfa(config) => Some(config.clone()),
        RawPhotometricInterpretation::LinearRaw if image.cpp != 1 => {
            return Err(RawError::unsupported(
                path,
                format!(
                    "linear (already demosaiced) raw data with {} channels; pgrf needs the sensor's mosaic",
                    image.cpp
                ),
            ))
        }
        RawPhotometricInterpretation::LinearRaw | RawPhotometricInterpretation::BlackIsZero => {
            None
        }
    };
    if image.cpp != 1 {
        return Err(RawError::unsupported(
            path,
            format!(
                "{} samples per pixel; pgrf needs a one-sample Bayer mosaic",
                image.cpp
            ),
        ));
    }
    let data = match &image.data {
        RawImageData::Integer(d) => d,
        RawImageData::Float(_) => {
            return Err(RawError::unsupported(
                path,
                "floating-point raw data; pgrf reads integer sensor data",
            ))
        }
    };
    if data.len() != image.width * image.height {
        return Err(RawError::decode(
            path,
            format!(
                "decoder returned {} samples for a {}x{} image",
                data.len(),
                image.width,
                image.height
            ),
        ));
    }
    Ok(config)
}

/// The visible area `(x0, y0, w, h)`: the active area when the file
/// declares one (it must fit the readout), else the whole readout.
fn visible_area(path: &Path, image: &RawImage) -> Result<(usize, usize, usize, usize)> {
    let (x0, y0, w, h) = match image.active_area {
        Some(r) => (r.p.x, r.p.y, r.d.w, r.d.h),
        None => (0, 0, image.width, image.height),
    };
    if w < 2 || h < 2 || x0 + w > image.width || y0 + h > image.height {
        return Err(RawError::decode(
            path,
            format!(
                "active area {w}x{h} at ({y0},{x0}) does not fit the {}x{} readout",
                image.width, image.height
            ),
        ));
    }
    Ok((x0, y0, w, h))
}

/// The Bayer phase of the visible area's first pixel (2x2 CFAs only).
fn bayer_phase(path: &Path, config: &CFAConfig, y0: usize, x0: usize) -> Result<Cfa> {
    let cfa_name = config.cfa.to_string();
    if config.cfa.width != 2 || config.cfa.height != 2 {
        return Err(RawError::unsupported(
            path,
            format!(
                "{}x{} colour filter array '{}' (X-Trans or other non-Bayer sensor); pgrf needs a 2x2 Bayer CFA",
                config.cfa.height, config.cfa.width, cfa_name
            ),
        ));
    }
    let full_cfa: Cfa = cfa_name
        .parse()
        .map_err(|e: pgrf_core::parse::ParseError| RawError::unsupported(path, e.to_string()))?;
    Ok(full_cfa.shifted(y0, x0))
}

/// The visible area's samples (an integer image, checked by
/// [`mosaic_layout`]).
fn visible_mosaic(image: &mut RawImage, (x0, y0, w, h): (usize, usize, usize, usize)) -> Vec<u16> {
    let full = image.width;
    let data = std::mem::replace(&mut image.data, RawImageData::Integer(Vec::new()));
    let RawImageData::Integer(mut v) = data else {
        unreachable!("mosaic_layout refuses floating-point data")
    };
    if x0 == 0 && w == full {
        // Full-width visible area (DNGs pgrf writes, many cameras): take the
        // decoder's buffer instead of copying 24 MB per 12 MP frame.
        v.truncate((y0 + h) * full);
        v.drain(..y0 * full);
        return v;
    }
    let mut m = Vec::with_capacity(w * h);
    for row in y0..y0 + h {
        m.extend_from_slice(&v[row * full + x0..row * full + x0 + w]);
    }
    m
}

/// Per-plane black level. rawler stores the DNG-style repeat pattern anchored
/// at the readout origin; shift it to the visible area and read each plane.
fn black_per_plane(
    path: &Path,
    image: &RawImage,
    cfa: Cfa,
    y0: usize,
    x0: usize,
) -> Result<[f32; 4]> {
    let bl = &image.blacklevel;
    if bl.levels.is_empty() || bl.width == 0 || bl.height == 0 {
        return Ok([0.0; 4]);
    }
    if bl.width > 2 || bl.height > 2 || bl.levels.len() < bl.width * bl.height {
        return Err(RawError::unsupported(
            path,
            format!(
                "black level repeat pattern {}x{} with {} values",
                bl.height,
                bl.width,
                bl.levels.len()
            ),
        ));
    }
    let mut out = [0.0f32; 4];
    for (plane, (dr, dc)) in cfa.offsets().into_iter().enumerate() {
        let r = (y0 + dr) % bl.height;
        let c = (x0 + dc) % bl.width;
        let v = bl.levels[r * bl.width + c];
        if v.d == 0 {
            return Err(RawError::decode(path, "black level with zero denominator"));
        }
        out[plane] = v.n as f32 / v.d as f32;
    }
    Ok(out)
}

/// All usable 3x3 matrices, ordered by illuminant code with daylight-class
/// illuminants (D65, D50, D55, daylight) last, as DNG puts the warmer
/// illuminant in slot 1.
fn color_matrices(image: &RawImage) -> Vec<ColorMatrix> {
    let daylight = |i: &Illuminant| {
        matches!(
            i,
            Illuminant::D65 | Illuminant::D50 | Illuminant::D55 | Illuminant::Daylight
        )
    };
    let mut v: Vec<(bool, u16, ColorMatrix)> = image
        .color_matrix
        .iter()
        .filter(|(_, m)| {
            m.len() >= 9 && m[..9].iter().all(|v| v.is_finite()) && m[..9].iter().any(|v| *v != 0.0)
        })
        .map(|(illum, m)| {
            let cm = ColorMatrix {
                xyz_to_cam: [[m[0], m[1], m[2]], [m[3], m[4], m[5]], [m[6], m[7], m[8]]],
                illuminant: format!("{illum:?}"),
            };
            (daylight(illum), u16::from(*illum), cm)
        })
        .collect();
    v.sort_by_key(|(d, code, _)| (*d, *code));
    v.into_iter().map(|(_, _, m)| m).collect()
}

fn exposure_of(m: &RawMetadata) -> (Option<u32>, Option<f64>) {
    let e = &m.exif;
    let iso = e
        .iso_speed_ratings
        .map(u32::from)
        .or(e.iso_speed)
        .or(e.recommended_exposure_index)
        .filter(|v| *v > 0);
    let exposure = e
        .exposure_time
        .filter(|r| r.d != 0 && r.n != 0)
        .map(|r| r.n as f64 / r.d as f64);
    (iso, exposure)
}
