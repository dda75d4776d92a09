//! Writing a `RawFrame` as a DNG: rawler's TIFF writer, pgrf's own raw-image
//! tags and pixel layout ([`tile_width`]: one LibRaw reads exactly).
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
use rawler::decoders::RawMetadata;
use rawler::dng::writer::DngWriter;
use rawler::dng::DNG_VERSION_V1_4;
use rawler::formats::tiff::writer::DirectoryWriter;
use rawler::formats::tiff::{CompressionMethod, PhotometricInterpretation, Rational, SRational};
use rawler::imgop::xyz::Illuminant;
use rawler::ljpeg92::LjpegCompressor;
use rawler::tags::{DngTag, ExifTag, TiffCommonTag};
use rawler::tiles::ImageTiler;
use std::io::{Cursor, Seek, Write};
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

/// Side of pgrf's LJPEG-92 tiles (TileLength always, TileWidth for frames
/// of 256 pixels or wider except 512: [`tile_width`]).
pub const DNG_TILE: usize = 256;

/// The TileWidth of a lossless DNG of a frame `width` pixels wide: one rule
/// that makes LibRaw (0.22, `lossless_dng_load_raw`) read every tile the
/// way it was written, found by `tests/reference/dng_width_sweep.py`:
///
/// - never wider than the frame. LibRaw ends a tile's row at the tile width
///   *or at the image width*, so a tile wider than the frame (256 for a frame
///   of 200) had the padding of each row read as the start of the next: 61 of
///   238 sizes came back wrong before, every one narrower than 256 or 512
///   wide. Frames under 16 pixels keep one 16-pixel tile (TIFF wants tile
///   widths in multiples of 16; LibRaw opens no frame under 22 pixels anyway).
/// - never exactly half the frame. For LJPEG of two or more components LibRaw
///   reads `clrs` JPEG rows' worth of pixels per row when `clrs * jwide ==
///   raw_width` (a layout of some cameras' DNGs); pgrf's tiles are
///   two-component JPEG rows of the tile width, so a frame of exactly two
///   tiles (512) was read with every row wrong. Such a frame gets one tile
///   column as wide as the frame.
///
/// Otherwise 256, what pgrf always wrote: the files of every other size are
/// unchanged, byte for byte.
pub fn tile_width(width: usize) -> usize {
    let tw = if width >= DNG_TILE {
        DNG_TILE
    } else {
        (width / 16 * 16).max(16)
    };
    if 2 * tw == width {
        width
    } else {
        tw
    }
}

/// Encode `frame` as DNG bytes; a frame with a masked strip
/// ([`crate::masked::MaskedStrip`]) is written as the readout it came from:
/// the strip's columns left of the visible pixels, declared in
/// `MaskedAreas`, the visible ones in `ActiveArea`.
pub fn encode_dng(frame: &RawFrame, opts: &DngOptions) -> Result<Vec<u8>> {
    frame.check_levels()?;
    let strip = frame.masked.as_ref().and_then(|m| m.strip.as_ref());
    if let Some(s) = strip {
        if s.columns % 2 != 0 || s.values.len() != s.columns * frame.height {
            return Err(RawError::MosaicInconsistent);
        }
        if frame.mosaic.len() != frame.width * frame.height {
            return Err(RawError::MosaicInconsistent);
        }
        let width = frame.width + s.columns;
        let mut mosaic = Vec::with_capacity(width * frame.height);
        for (m, v) in s
            .values
            .chunks_exact(s.columns)
            .zip(frame.mosaic.chunks_exact(frame.width))
        {
            mosaic.extend_from_slice(m);
            mosaic.extend_from_slice(v);
        }
        let readout = RawFrame {
            width,
            mosaic,
            masked: None,
            ..frame.clone()
        };
        return encode_readout(&readout, s.columns, opts);
    }
    encode_readout(frame, 0, opts)
}

/// The DNG NewRawImageDigest (tag 51111, DNG 1.4) of a raw image of one
/// sample per pixel: the MD5 of every sample in row-scan order, each as 16
/// bits little-endian. Written with every DNG so that a file damaged
/// inside its compressed tiles, whose structure still reads, is told from
/// a whole one ([`pixels_intact`]); Adobe's DNG SDK checks it the same way.
pub fn raw_image_digest(samples: &[u16]) -> [u8; 16] {
    let mut md5 = md5::Context::new();
    for chunk in samples.chunks(65536) {
        let bytes: Vec<u8> = chunk.iter().flat_map(|v| v.to_le_bytes()).collect();
        md5.consume(&bytes);
    }
    md5.finalize().0
}

/// Whether the DNG `bytes`, decoded as `frame`, hold the pixels they were
/// written with: its NewRawImageDigest equals the digest of the decoded
/// raw image. A file without the tag (another writer's, an older pgrf's,
/// a FITS file) or with masked columns beside the image (the digest covers
/// them too) passes: nothing to check it against.
pub fn pixels_intact(bytes: &[u8], frame: &RawFrame) -> bool {
    match crate::container::raw_digest(bytes) {
        None => true,
        Some(_) if frame.masked.is_some() => true,
        Some(stored) => stored == raw_image_digest(&frame.mosaic),
    }
}

/// [`encode_dng`] of a readout whose first `masked` columns are shielded.
fn encode_readout(frame: &RawFrame, masked: usize, opts: &DngOptions) -> Result<Vec<u8>> {
    if frame.mosaic.len() != frame.width * frame.height {
        return Err(RawError::MosaicInconsistent);
    }
    if frame.width > u16::MAX as usize || frame.height > u16::MAX as usize {
        return Err(RawError::TooLargeForDng {
            width: frame.width,
            height: frame.height,
        });
    }
    let exif = exif_for(frame);
    quietly(|| -> Result<Vec<u8>> {
        let mut buf = Cursor::new(Vec::with_capacity(frame.mosaic.len() * 2 + 65536));
        let mut dng = DngWriter::new(&mut buf, DNG_VERSION_V1_4).map_err(dng_fault)?;
        // The raw image in IFD0, its tags and pixels written by pgrf (the
        // tile layout is LibRaw's business: [`tile_width`]); the pixels go
        // before the metadata's blobs, as rawler's writer placed them.
        dng.root_ifd_mut()
            .add_tag(TiffCommonTag::NewSubFileType, 0_u32);
        raw_tags(dng.root_ifd_mut(), frame, masked);
        match opts.compression {
            Compression::Lossless => put_ljpeg(&mut dng, frame)?,
            Compression::Uncompressed => put_uncompressed(&mut dng, frame)?,
        }
        // What a later run checks its pixels against (`pixels_intact`).
        dng.root_ifd_mut().add_tag(
            DngTag::NewRawImageDigest,
            &raw_image_digest(&frame.mosaic)[..],
        );
        if let Some(np) = &frame.noise_profile {
            let flat: Vec<f64> = np.iter().flatten().copied().collect();
            dng.root_ifd_mut()
                .add_tag(rawler::tags::DngTag::NoiseProfile, flat.as_slice());
        }
        let root = dng.root_ifd_mut();
        root.add_tag(TiffCommonTag::Make, frame.make.as_str());
        root.add_tag(TiffCommonTag::Model, frame.model.as_str());
        let unique = format!("{} {}", frame.make, frame.model);
        root.add_tag(DngTag::UniqueCameraModel, unique.as_str());
        dng.load_metadata(&exif).map_err(dng_fault)?;
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
        dng.close().map_err(dng_fault)?;
        Ok(buf.into_inner())
    })
    .map_err(dng_fault)?
}

/// The DNG writer's (or a panic's) complaint as the error that names the
/// format: the data given could not be encoded.
fn dng_fault(reason: impl std::fmt::Display) -> RawError {
    RawError::Encode {
        format: "DNG",
        reason: reason.to_string(),
    }
}

/// Encode `frame` as DNG (same pixels, CFA, levels, colour matrices, white
/// balance and EXIF) and write it to `path` atomically.
pub fn write_dng(frame: &RawFrame, path: &Path, opts: &DngOptions) -> Result<()> {
    let bytes = encode_dng(frame, opts)?;
    Ok(write_atomic(path, &bytes)?)
}

/// The raw image's description (size, levels, CFA, photometric
/// interpretation), with the types rawler's writer gave each tag.
fn raw_tags(ifd: &mut DirectoryWriter, frame: &RawFrame, masked: usize) {
    let (w, h) = (frame.width, frame.height);
    ifd.add_tag(TiffCommonTag::ImageWidth, w as u32);
    ifd.add_tag(TiffCommonTag::ImageLength, h as u32);
    ifd.add_tag(
        DngTag::ActiveArea,
        [0_u16, masked as u16, h as u16, w as u16],
    );
    if masked > 0 {
        ifd.add_tag(DngTag::MaskedAreas, [0_u16, 0, h as u16, masked as u16]);
    }
    ifd.add_tag(ExifTag::PlanarConfiguration, 1_u16);
    ifd.add_tag(
        DngTag::DefaultScale,
        [Rational::new(1, 1), Rational::new(1, 1)],
    );
    ifd.add_tag(DngTag::BestQualityScale, Rational::new(1, 1));
    if frame.white <= u16::MAX as u32 {
        ifd.add_tag(DngTag::WhiteLevel, &vec![frame.white as u16]);
    } else {
        ifd.add_tag(DngTag::WhiteLevel, &vec![frame.white]);
    }
    // Black level as a 2x2 repeat pattern anchored at pixel (0, 0).
    let black: Vec<Rational> = (0..2)
        .flat_map(|r| (0..2).map(move |c| (r, c)))
        .map(|(r, c)| rational_level(frame.black[frame.cfa.plane_at(r, c)]))
        .collect();
    ifd.add_tag(DngTag::BlackLevelRepeatDim, [2_u16, 2]);
    if black.iter().all(|x| x.d == 1) {
        let whole: Vec<u32> = black.iter().map(|x| x.n).collect();
        if whole.iter().all(|x| *x <= u16::MAX as u32) {
            ifd.add_tag(
                DngTag::BlackLevel,
                &whole.iter().map(|x| *x as u16).collect::<Vec<u16>>(),
            );
        } else {
            ifd.add_tag(DngTag::BlackLevel, &whole);
        }
    } else {
        ifd.add_tag(DngTag::BlackLevel, black.as_slice());
    }
    ifd.add_tag(TiffCommonTag::SamplesPerPixel, 1_u16);
    // A monochrome frame is a one-sample LinearRaw image: how the DNG
    // specification and Leica's Monochrom DNGs store a sensor without a
    // colour filter. Its black pattern still repeats 2x2.
    if frame.mono {
        ifd.add_tag(
            TiffCommonTag::PhotometricInt,
            PhotometricInterpretation::LinearRaw,
        );
    } else {
        let cfa = CFA::new(frame.cfa.name());
        ifd.add_tag(
            TiffCommonTag::CFARepeatPatternDim,
            [cfa.width as u16, cfa.height as u16],
        );
        ifd.add_tag(TiffCommonTag::CFAPattern, &cfa.flat_pattern()[..]);
        ifd.add_tag(
            TiffCommonTag::PhotometricInt,
            PhotometricInterpretation::CFA,
        );
        ifd.add_tag(DngTag::CFAPlaneColor, &PlaneColor::new("RGB"));
        ifd.add_tag(DngTag::CFALayout, 1_u16); // square
    }
}

/// The pixels as LJPEG-92 tiles of [`tile_width`] x [`DNG_TILE`] (the last
/// column and row padded by repeating the edge), predictor 1; a CFA frame's
/// rows as two-component JPEG rows (the two colours of a row alternate), a
/// monochrome frame's as one component. The tiles are compressed in
/// parallel.
fn put_ljpeg<W: Write + Seek>(dng: &mut DngWriter<W>, frame: &RawFrame) -> Result<()> {
    use rayon::prelude::*;
    let (tw, th) = (tile_width(frame.width), DNG_TILE);
    // The frame's bits, or more when a sample needs them (LJPEG-92 refuses
    // a sample above its precision).
    let top = frame.mosaic.iter().copied().max().unwrap_or(0);
    let bps = frame
        .bits
        .max(crate::frame::bits_for(top as u32))
        .clamp(1, 16) as u8;
    let components = if frame.mono { 1 } else { 2 };
    let tiler = ImageTiler::new(&frame.mosaic, frame.width, frame.height, 1, tw, th);
    let tiles = (0..tiler.tile_count())
        .into_par_iter()
        .map(|i| {
            let tile = tiler.build_tile(i);
            LjpegCompressor::new(&tile, tw / components, th, components, bps, 1, 0, 0)
                .and_then(|c| c.encode())
                .map_err(|e| dng_fault(format!("LJPEG encoding failed: {e}")))
        })
        .collect::<Result<Vec<Vec<u8>>>>()?;
    let (mut offsets, mut sizes) = (Vec::new(), Vec::new());
    for t in &tiles {
        offsets.push(dng.dng.write_data(t).map_err(dng_fault)?);
        sizes.push(t.len() as u32);
    }
    let ifd = dng.root_ifd_mut();
    ifd.add_tag(TiffCommonTag::Compression, CompressionMethod::ModernJPEG);
    ifd.add_tag(TiffCommonTag::BitsPerSample, &vec![bps as u16]);
    ifd.add_tag(TiffCommonTag::SampleFormat, &vec![1_u16]);
    ifd.add_tag(TiffCommonTag::TileOffsets, &offsets);
    ifd.add_tag(TiffCommonTag::TileByteCounts, &sizes);
    ifd.add_tag(TiffCommonTag::TileWidth, tw as u16);
    ifd.add_tag(TiffCommonTag::TileLength, th as u16);
    Ok(())
}

/// The pixels as 16-bit little-endian strips: one strip up to 100 rows,
/// strips of 256 rows above. RowsPerStrip is one number (TIFF 6.0: the last
/// strip holds what is left); a count per strip is read as one strip by
/// tifffile and others.
fn put_uncompressed<W: Write + Seek>(dng: &mut DngWriter<W>, frame: &RawFrame) -> Result<()> {
    let rows = if frame.height > 100 {
        256
    } else {
        frame.height.max(1)
    };
    let (mut offsets, mut sizes) = (Vec::new(), Vec::new());
    for strip in frame.mosaic.chunks(rows * frame.width.max(1)) {
        offsets.push(dng.dng.write_data_u16_le(strip).map_err(dng_fault)?);
        sizes.push(std::mem::size_of_val(strip) as u32);
    }
    let ifd = dng.root_ifd_mut();
    ifd.add_tag(TiffCommonTag::Compression, CompressionMethod::None);
    ifd.add_tag(TiffCommonTag::SampleFormat, &vec![1_u16]);
    ifd.add_tag(TiffCommonTag::BitsPerSample, &vec![16_u16]);
    ifd.add_tag(TiffCommonTag::StripOffsets, &offsets);
    ifd.add_tag(TiffCommonTag::StripByteCounts, &sizes);
    ifd.add_tag(TiffCommonTag::RowsPerStrip, rows as u32);
    Ok(())
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

    /// A sample above the frame's bits (a result restored up to a white
    /// raised by --white) widens BitsPerSample instead of failing the LJPEG
    /// encoder ("Sample overflow"), and reads back exactly.
    #[test]
    fn samples_above_the_frames_bits_are_written_whole() {
        let mut mosaic = vec![600u16; 64 * 32];
        mosaic[77] = 40000;
        let mut f =
            RawFrame::from_mosaic(64, 32, mosaic.clone(), crate::Cfa::Rggb, [512.0; 4], 65535)
                .unwrap();
        f.bits = 14;
        let bytes = encode_dng(&f, &DngOptions::default()).unwrap();
        let back = crate::decode_bytes(std::path::Path::new("t.dng"), &bytes, &Default::default())
            .unwrap();
        assert!(back.mosaic == mosaic);
        assert_eq!(back.bits, 16);
    }

    /// Uncompressed strips carry one RowsPerStrip value (TIFF 6.0's count 1;
    /// the last strip is shorter), and the frame reads back exactly.
    #[test]
    fn uncompressed_strips_have_one_rows_per_strip() {
        use rawler::formats::tiff::reader::{GenericTiffReader, TiffReader};
        let (w, h) = (40, 600);
        let mosaic: Vec<u16> = (0..w * h).map(|i| (i * 7 % 4000) as u16).collect();
        let f = RawFrame::from_mosaic(w, h, mosaic.clone(), crate::Cfa::Rggb, [512.0; 4], 16383)
            .unwrap();
        let options = DngOptions {
            compression: Compression::Uncompressed,
            ..Default::default()
        };
        let bytes = encode_dng(&f, &options).unwrap();
        let tiff = GenericTiffReader::new_with_buffer(&bytes, 0, 0, None).unwrap();
        let ifd = tiff.root_ifd();
        let rows = ifd.get_entry(TiffCommonTag::RowsPerStrip).unwrap();
        assert_eq!(rows.count(), 1);
        assert_eq!(rows.force_u32(0), 256);
        assert_eq!(
            ifd.get_entry(TiffCommonTag::StripOffsets).unwrap().count(),
            3
        );
        let back = crate::decode_bytes(std::path::Path::new("t.dng"), &bytes, &Default::default())
            .unwrap();
        assert!(back.mosaic == mosaic);
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
