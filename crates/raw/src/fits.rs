//! FITS frames of cooled astronomy cameras: read a raw frame, write a master.
//!
//! Mono CCD/CMOS and one-shot-colour (Bayer) astro cameras record FITS, not a
//! camera RAW, so bias, dark and flat frames for calibration arrive as FITS and
//! the masters pgrf makes from them go back out as FITS for the stacking tools
//! (Siril, PixInsight, ASTAP) to use.
//!
//! Reading goes through `fitsrs` (the CDS Strasbourg's pure-Rust reader),
//! which yields the stored sample values; BZERO/BSCALE are applied here and
//! the result is brought to the u16 ADU the rest of pgrf works in, or refused
//! with the reason (a calibrated or demosaiced frame is not a sensor's raw
//! frame). Only the primary HDU's image is read. Writing is a small encoder of
//! pgrf's own (fitsrs has none): BITPIX 16 with BZERO 32768 for integer
//! masters, BITPIX -32 for averaged ones.
//!
//! # Bayer phase: BAYERPAT, ROWORDER, XBAYROFF, YBAYROFF
//!
//! The convention is the one Siril and CCDciel introduced with the ROWORDER
//! keyword in 2020 and that INDI, INDIGO, N.I.N.A., SharpCap, FireCapture,
//! MaxIm DL, PixInsight, ASTAP and APT write or honour (Siril's "FITS
//! orientation" page, free-astro.org, now in siril.readthedocs.io,
//! file-formats/FITS.html, "Orientation of FITS images"):
//!
//! - BAYERPAT names the colours of the top-left 2x2 cell of the image *as
//!   seen top-down*, the order camera drivers read the sensor in.
//! - ROWORDER says how the rows are stored: `TOP-DOWN` (stored row 0 is the
//!   image's top row, what drivers write) or `BOTTOM-UP` (stored row 0 is the
//!   bottom row, the FITS standard's display convention). For the Bayer
//!   phase, a file without ROWORDER is read as TOP-DOWN, as Siril's
//!   debayering does by default (`ROW_ORDER_HEADER_TOPDOWN`: from the
//!   header, else top-down). Its rows, though, are bottom-up by the FITS
//!   convention (Siril loads such a file as it is and flips a TOP-DOWN one),
//!   so what pgrf writes from it says BOTTOM-UP ([`RowOrder`],
//!   [`crate::RawFrame::row_order`]).
//! - XBAYROFF/YBAYROFF shift where the pattern starts reading, in columns and
//!   rows; only their parity matters. An odd XBAYROFF turns RGGB into GRBG,
//!   an odd YBAYROFF turns RGGB into GBRG.
//!
//! Siril's `adjust_Bayer_pattern` (src/algos/demosaicing.c) implements
//! exactly this on the rows as stored: for a BOTTOM-UP image it flips the
//! 2x2 pattern vertically "accounting for offset in case the image does not
//! have an even number of rows", then applies the offsets. Worked out on the
//! stored rows: stored row `s` of a BOTTOM-UP image of height `H` is the
//! top-down row `H - 1 - s`, whose pattern row is `(H - 1 - s + YBAYROFF) mod
//! 2`, which has the parity of `H - 1 + YBAYROFF + s`. So the phase of
//! `data[0]` (stored row 0, column 0) is BAYERPAT shifted by
//! `dy = (YBAYROFF + (H - 1 if BOTTOM-UP else 0)) mod 2` rows and
//! `dx = XBAYROFF mod 2` columns. For RGGB, BOTTOM-UP, even height: GBRG (the
//! vertical flip Siril's page cites); odd height: RGGB (stored row 0 is then
//! an even top-down row). Rows are never flipped: [`FitsImage::data`] is in
//! the stored order and [`FitsImage::bayer`] is the phase of that order.
//!
//! BAYERPAT = 'TRUE' (or the logical T that some programs write to mean
//! "this is a colour sensor") is refused: it says there is a colour filter
//! but not its phase, and neither guessing RGGB (a wrong guess swaps red and
//! blue through calibration and training) nor reading the frame as
//! monochrome (it is not) is safe. Other values that are not one of the four
//! Bayer phases (X-Trans, CMYG) are refused too. An empty BAYERPAT or the
//! logical F mean no colour filter.

use crate::cfa::Cfa;
use crate::error::{RawError, Result};
use crate::panic_guard;
use fitsrs::card::Value;
use fitsrs::hdu::header::ValueMap;
use fitsrs::{Fits, Pixels, HDU};
use serde::Serialize;
use std::io::Cursor;
use std::path::Path;

/// FITS headers and data come in blocks of this many bytes.
const BLOCK: usize = 2880;
/// One header card.
const CARD: usize = 80;
/// Largest accepted NAXIS1/NAXIS2: no camera sensor is wider, and the bound
/// keeps hostile headers from asking for absurd buffers.
const MAX_SIDE: u64 = 65536;

/// One 2-D image of a FITS file's primary HDU, as pgrf uses it.
///
/// The samples are the camera's ADU as u16, in the file's stored row order,
/// with the metadata calibration needs (exposure, gain, temperature) and the
/// Bayer phase of the stored order.
#[derive(Clone, Debug, PartialEq)]
pub struct FitsImage {
    /// Width in pixels (NAXIS1).
    pub width: usize,
    /// Height in pixels (NAXIS2).
    pub height: usize,
    /// Samples in ADU, row-major, rows in the order stored in the file (no flip).
    pub data: Vec<u16>,
    /// ROWORDER as the header states it; `None` when it has none (the rows
    /// are then bottom-up by the FITS convention).
    pub row_order: Option<RowOrder>,
    /// Bayer phase of `data[0]` (stored row 0, column 0) when the header
    /// declares a colour filter (BAYERPAT, with ROWORDER and XBAYROFF/YBAYROFF
    /// applied as the module documentation explains); `None`: monochrome.
    pub bayer: Option<Cfa>,
    /// BITPIX of the file (8, 16, 32, 64, -32, -64), so `pgrf info` can say
    /// what the file held before conversion.
    pub bitpix: i32,
    /// Full-scale value of the samples: 255 for unscaled BITPIX 8, 65535
    /// otherwise, or SATURATE (else DATAMAX) when the header gives a smaller
    /// integer one that no sample exceeds.
    pub white: u32,
    /// When the header's SATURATE (else DATAMAX) is a smaller integer than
    /// full scale but samples exceed it, what is wrong, for one line: a
    /// frame read for use is refused unless a white level is given
    /// (`--white`), since neither the header's level nor full scale is known
    /// to be where the camera clips. `white` is then full scale.
    pub white_conflict: Option<String>,
    /// Exposure in seconds: EXPTIME, else EXPOSURE.
    pub exposure_s: Option<f64>,
    /// EGAIN: the system gain in electrons per ADU, when the capture program
    /// knows it.
    pub egain_e_per_adu: Option<f64>,
    /// GAIN: in most drivers (ZWO, QHY, INDI) the camera's gain *setting*,
    /// not electrons per ADU; kept apart from EGAIN so the two are never
    /// confused.
    pub gain_setting: Option<f64>,
    /// Sensor temperature in degrees Celsius: CCD-TEMP, else CCD_TEMP.
    pub temperature_c: Option<f32>,
    /// ISOSPEED (DSLRs saved as FITS by capture programs).
    pub iso: Option<u32>,
    /// INSTRUME: the camera's name.
    pub instrument: Option<String>,
    /// DATE-OBS: the start of the exposure, as written (ISO 8601).
    pub date_obs: Option<String>,
    /// XBINNING x YBINNING: pixels summed per stored pixel, when the header
    /// states either (the other is then 1).
    pub binning: Option<(u32, u32)>,
    /// How samples that were not 16-bit integers were brought to u16 (for
    /// example "BITPIX -32 in 0..1 scaled by 65535"), for `pgrf info`;
    /// `None` for BITPIX 16 read as stored.
    pub conversion: Option<String>,
}

/// How a FITS file stores its rows: its ROWORDER keyword. pgrf never
/// flips rows; it keeps the stored order and writes back the keyword that
/// says which it is, so a master lines up with the lights it was made for
/// in every tool that honours the keyword.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, serde::Deserialize)]
pub enum RowOrder {
    /// Stored row 0 is the image's top row (what camera drivers write).
    #[serde(rename = "TOP-DOWN")]
    TopDown,
    /// Stored row 0 is the bottom row (the FITS standard's convention, and
    /// what a file without ROWORDER is).
    #[serde(rename = "BOTTOM-UP")]
    BottomUp,
}

impl RowOrder {
    /// The ROWORDER value: "TOP-DOWN" or "BOTTOM-UP".
    pub fn keyword(self) -> &'static str {
        match self {
            RowOrder::TopDown => "TOP-DOWN",
            RowOrder::BottomUp => "BOTTOM-UP",
        }
    }
}

/// What a FITS frame's header says that the other fields of a [`RawFrame`](crate::RawFrame) do not
/// hold: kept so `pgrf info` can show it and calibration can compare its
/// gain with the header's. It is the one field of a [`RawFrame`](crate::RawFrame)
/// that only a FITS file fills ([`RawFrame::fits`](crate::RawFrame::fits)).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FitsHeader {
    /// BITPIX of the file (8, 16, 32, -32, -64).
    pub bitpix: i32,
    /// EGAIN: electrons per ADU as the camera driver states it.
    pub egain_e_per_adu: Option<f64>,
    /// GAIN: in most drivers (ZWO, QHY) a gain setting, not electrons per ADU.
    pub gain_setting: Option<f64>,
    /// DATE-OBS, as written.
    pub date_obs: Option<String>,
    /// ROWORDER as the header states it; `None` without one.
    pub row_order: Option<RowOrder>,
    /// XBINNING x YBINNING, when the header states either: masters and
    /// lights must be binned alike.
    pub binning: Option<(u32, u32)>,
    /// How samples that were not unsigned 16-bit integers became DN.
    pub conversion: Option<String>,
}

/// Whether `bytes` start like a FITS file: the first card is `SIMPLE = T`.
///
/// Used to route a file to [`read_fits`] before any camera-RAW decoder sees
/// it.
pub fn is_fits(bytes: &[u8]) -> bool {
    if bytes.len() < CARD || &bytes[..9] != b"SIMPLE  =" {
        return false;
    }
    let value = value_field(&bytes[..CARD]);
    value == Some("T")
}

/// Read the primary image of a FITS file held in memory.
///
/// `name` is only used in error messages. The header is checked before any
/// buffer is sized from it; every refusal is one line naming the keyword or
/// value at fault. See the module documentation for the Bayer convention.
pub fn read_fits(name: &Path, bytes: &[u8]) -> Result<FitsImage> {
    if bytes.is_empty() {
        return Err(RawError::decode(name, "file is empty"));
    }
    if !is_fits(bytes) {
        return Err(RawError::decode(
            name,
            "not a FITS file: the first card is not SIMPLE = T",
        ));
    }
    // fitsrs asserts on some malformed input; a panic there becomes an error.
    panic_guard::quietly(|| read_primary(name, bytes)).map_err(|m| RawError::decode(name, m))?
}

/// The samples of a FITS file in DN as floats, unrounded, beside what
/// [`read_fits`] reads of it (the file is checked and refused as there): a
/// master written as 32-bit floats (`encode_fits_master`) knows its mean to
/// a fraction of a DN, which [`FitsImage::data`]'s integers round away, and
/// light-frame reduction subtracts it unrounded as every stacking program
/// does. Normalised 0..1 floats are scaled by 65535 as [`read_fits`] scales
/// them; integer samples are the same values as [`FitsImage::data`].
pub fn read_fits_samples(name: &Path, bytes: &[u8]) -> Result<(FitsImage, Vec<f32>)> {
    let image = read_fits(name, bytes)?;
    if image.bitpix > 0 {
        let samples = image.data.iter().map(|&v| f32::from(v)).collect();
        return Ok((image, samples));
    }
    let scale = if (image.conversion.as_deref()).is_some_and(|c| c.ends_with("scaled by 65535")) {
        65535.0
    } else {
        1.0
    };
    let n = image.width * image.height;
    let decode = |m: String| RawError::decode(name, m);
    let samples = panic_guard::quietly(|| -> Result<Vec<f32>> {
        let mut fits = Fits::from_reader(Cursor::new(bytes));
        let Some(Ok(HDU::Primary(hdu))) = fits.next() else {
            return Err(decode("no primary HDU".into()));
        };
        let header = hdu.get_header();
        let bzero = number(header, "BZERO").map_err(decode)?.unwrap_or(0.0);
        let bscale = number(header, "BSCALE").map_err(decode)?.unwrap_or(1.0);
        let physical = |v: f64| ((bzero + bscale * v) * scale) as f32;
        let samples: Vec<f32> = match fits.get_data(&hdu).pixels() {
            Pixels::F32(it) => it.take(n).map(|v| physical(f64::from(v))).collect(),
            Pixels::F64(it) => it.take(n).map(physical).collect(),
            _ => return Err(decode("BITPIX changed between two reads".into())),
        };
        Ok(samples)
    })
    .map_err(decode)??;
    Ok((image, samples))
}

/// A header card pgrf writes: a keyword, its value and a comment.
#[derive(Clone, Debug, PartialEq)]
pub enum FitsValue {
    /// An integer, written right-justified to column 30.
    Int(i64),
    /// A real number, written right-justified to column 30 in the shortest
    /// form that reads back to the same value (must be finite).
    Float(f64),
    /// A string, written in single quotes (printable ASCII only).
    Str(String),
    /// A logical, written as T or F in column 30.
    Bool(bool),
}

/// One header card for the encoders: `KEY = value / comment`.
#[derive(Clone, Debug, PartialEq)]
pub struct FitsCard {
    /// Keyword: 1 to 8 characters of A-Z, 0-9, '-' and '_'.
    pub key: String,
    /// The value.
    pub value: FitsValue,
    /// Free text after " / " (printable ASCII); empty for none.
    pub comment: String,
}

impl FitsCard {
    /// A card; the encoders validate it.
    pub fn new(key: &str, value: FitsValue, comment: &str) -> Self {
        FitsCard {
            key: key.to_string(),
            value,
            comment: comment.to_string(),
        }
    }
}

/// Encode a u16 image as BITPIX 16 with BZERO 32768 (the unsigned-16
/// convention every astro camera driver uses), big-endian, in 2880-byte
/// blocks: the file a stacking program expects for an integer master.
///
/// `cards` follow the mandatory ones (SIMPLE, BITPIX, NAXIS, NAXIS1, NAXIS2,
/// BZERO, BSCALE); they may not repeat those nor each other.
pub fn encode_fits_u16(
    width: usize,
    height: usize,
    data: &[u16],
    cards: &[FitsCard],
) -> Result<Vec<u8>> {
    check_geometry(width, height, data.len())?;
    let fixed = [
        FitsCard::new(
            "BZERO",
            FitsValue::Int(32768),
            "offset data range to that of unsigned short",
        ),
        FitsCard::new("BSCALE", FitsValue::Int(1), "default scaling factor"),
    ];
    let mut out = header(16, width, height, &fixed, cards)?;
    out.reserve(padded(data.len() * 2));
    for &v in data {
        // stored = physical - BZERO, i.e. the sign bit flipped.
        out.extend_from_slice(&(v ^ 0x8000).to_be_bytes());
    }
    out.resize(padded(out.len()), 0);
    Ok(out)
}

/// Encode an f32 image as BITPIX -32 (IEEE big-endian), for averaged masters
/// whose fractional ADU would be lost in integers. NaN and infinities are
/// refused, as the reader refuses them.
pub fn encode_fits_f32(
    width: usize,
    height: usize,
    data: &[f32],
    cards: &[FitsCard],
) -> Result<Vec<u8>> {
    encode_fits_f32_history(width, height, data, cards, &[])
}

/// [`encode_fits_f32`] with HISTORY cards after the caller's, one per entry
/// of `history` (longer entries continue on further cards): how a reduced
/// light frame records the steps that made it, as FITS tools show them.
pub fn encode_fits_f32_history(
    width: usize,
    height: usize,
    data: &[f32],
    cards: &[FitsCard],
    history: &[String],
) -> Result<Vec<u8>> {
    check_geometry(width, height, data.len())?;
    let bad = data.iter().filter(|v| !v.is_finite()).count();
    if bad > 0 {
        return Err(RawError::NonFiniteMaster {
            bad,
            samples: data.len(),
        });
    }
    let mut out = header(-32, width, height, &[], cards)?;
    // Each HISTORY card replaces part of the END card's block: END is
    // written again after them.
    out.truncate(out.len() - padding_after_end(&out));
    for text in history {
        if !text.bytes().all(|b| (0x20..=0x7e).contains(&b)) {
            return Err(RawError::FitsCard {
                key: "HISTORY".into(),
                reason: "HISTORY text must be printable ASCII".into(),
            });
        }
        let chars: Vec<char> = text.chars().collect();
        for piece in chars.chunks(CARD - 8) {
            let piece: String = piece.iter().collect();
            out.extend_from_slice(format!("{:<80}", format!("HISTORY {piece}")).as_bytes());
        }
    }
    out.extend_from_slice(format!("{:<80}", "END").as_bytes());
    out.resize(padded(out.len()), b' ');
    out.reserve(padded(data.len() * 4));
    for &v in data {
        out.extend_from_slice(&v.to_be_bytes());
    }
    out.resize(padded(out.len()), 0);
    Ok(out)
}

// ---------------------------------------------------------------- reading

fn read_primary(name: &Path, bytes: &[u8]) -> Result<FitsImage> {
    let decode = |m: String| RawError::decode(name, m);
    let unsupported = |m: String| RawError::unsupported(name, m);

    // fitsrs multiplies the axis lengths (and would overflow on hostile
    // ones) while it parses; the ones pgrf cannot use are named first.
    if let Some(why) = oversized_axis(bytes) {
        return Err(decode(why));
    }
    let mut fits = Fits::from_reader(Cursor::new(bytes));
    let hdu = match fits.next() {
        Some(Ok(HDU::Primary(hdu))) => hdu,
        Some(Ok(_)) | None => return Err(decode("no primary HDU".into())),
        Some(Err(e)) => return Err(decode(header_error(bytes, &e))),
    };
    let header = hdu.get_header();
    let image = header.get_xtension();
    let naxis: Vec<u64> = image.get_naxis().to_vec();
    let bitpix = image.get_bitpix() as i8 as i32;
    let data_start = usize::try_from(hdu.get_data_unit_byte_offset())
        .map_err(|_| decode("data offset does not fit in memory".into()))?;

    // Geometry, before anything is sized from the header.
    let (width, height) = match naxis.as_slice() {
        [] => return Err(empty_primary(name, bytes, data_start)),
        [w, h] | [w, h, 1] => (*w, *h),
        [_, _, 3] => {
            return Err(unsupported(
                "already demosaiced colour (3 planes); pgrf needs the sensor's raw frame".into(),
            ))
        }
        [_, _, n] => {
            return Err(unsupported(format!(
                "NAXIS3 = {n}: a cube of {n} planes; pgrf reads one 2-D frame"
            )))
        }
        other => {
            return Err(unsupported(format!(
                "NAXIS = {}: pgrf reads 2-D images (NAXIS 2, or 3 with NAXIS3 = 1)",
                other.len()
            )))
        }
    };
    for (key, v) in [("NAXIS1", width), ("NAXIS2", height)] {
        if !(2..=MAX_SIDE).contains(&v) {
            return Err(decode(format!(
                "{key} = {v} is outside 2..={MAX_SIDE} pixels"
            )));
        }
    }
    if let Some(why) = crate::container::limits::too_many_pixels(width, height) {
        return Err(decode(why));
    }
    let sample_bytes = u64::from(bitpix.unsigned_abs() / 8);
    let need = width * height * sample_bytes; // <= 65536^2 * 8: no overflow
    let have = (bytes.len() - data_start.min(bytes.len())) as u64;
    if need > have {
        return Err(decode(format!(
            "truncated: the image needs {need} bytes after the header, the file has {have}"
        )));
    }
    let (width, height) = (width as usize, height as usize);
    let n = width * height;
    crate::memory::check_frame(name, "decoding", width, height, crate::memory::DECODE)?;

    // Scaling keywords.
    let bzero = number(header, "BZERO").map_err(decode)?.unwrap_or(0.0);
    let bscale = number(header, "BSCALE").map_err(decode)?.unwrap_or(1.0);
    if bscale == 0.0 {
        return Err(decode(
            "BSCALE = 0: every sample would read as BZERO".into(),
        ));
    }
    let blank = if bitpix > 0 {
        integer(header, "BLANK").map_err(decode)?
    } else {
        None
    };

    // Metadata, checked before the pixels are converted.
    let exposure = match number(header, "EXPTIME").map_err(decode)? {
        Some(t) => Some(("EXPTIME", t)),
        None => number(header, "EXPOSURE")
            .map_err(decode)?
            .map(|t| ("EXPOSURE", t)),
    };
    if let Some((key, t)) = exposure {
        if t < 0.0 {
            return Err(decode(format!("{key} = {t} s is negative")));
        }
    }
    let egain_e_per_adu = number(header, "EGAIN").map_err(decode)?;
    if let Some(g) = egain_e_per_adu {
        if g <= 0.0 {
            return Err(decode(format!("EGAIN = {g} e-/ADU is not positive")));
        }
    }
    let gain_setting = number(header, "GAIN").map_err(decode)?;
    let temperature = match number(header, "CCD-TEMP").map_err(decode)? {
        Some(t) => Some(("CCD-TEMP", t)),
        None => number(header, "CCD_TEMP")
            .map_err(decode)?
            .map(|t| ("CCD_TEMP", t)),
    };
    if let Some((key, t)) = temperature {
        if !(-273.15..=200.0).contains(&t) {
            return Err(decode(format!(
                "{key} = {t} is not a sensor temperature in degrees Celsius"
            )));
        }
    }
    let iso = match integer(header, "ISOSPEED").map_err(decode)? {
        None => None,
        Some(v) if (1..=i64::from(u32::MAX)).contains(&v) => Some(v as u32),
        Some(v) => return Err(decode(format!("ISOSPEED = {v} is not a positive ISO"))),
    };
    let instrument = string(header, "INSTRUME").map_err(decode)?;
    let date_obs = string(header, "DATE-OBS").map_err(decode)?;
    let binning = binning(header).map_err(decode)?;
    let row_order = row_order(header).map_err(decode)?;
    let bayer = bayer_phase(name, header, height, row_order)?;

    // Pixels.
    let (data, conversion) = match fits.get_data(&hdu).pixels() {
        Pixels::U8(it) => integers(it.map(i64::from), n, 8, bzero, bscale, blank),
        Pixels::I16(it) => integers(it.map(i64::from), n, 16, bzero, bscale, blank),
        Pixels::I32(it) => integers(it.map(i64::from), n, 32, bzero, bscale, blank),
        Pixels::I64(it) => integers(it, n, 64, bzero, bscale, blank),
        Pixels::F32(it) => floats(it.map(f64::from), n, -32, bzero, bscale),
        Pixels::F64(it) => floats(it, n, -64, bzero, bscale),
    }
    .map_err(|m| match m {
        Refusal::Decode(m) => decode(m),
        Refusal::Unsupported(m) => unsupported(m),
    })?;

    // Full scale.
    let normalised = bitpix < 0
        && conversion
            .as_deref()
            .is_some_and(|c| c.ends_with("scaled by 65535"));
    let max_sample = u32::from(data.iter().copied().max().unwrap_or(0));
    let mut white = if bitpix == 8 && bzero == 0.0 && bscale == 1.0 {
        255
    } else {
        65535
    };
    let mut white_conflict = None;
    if !normalised {
        for key in ["SATURATE", "DATAMAX"] {
            if let Some(v) = number(header, key).map_err(decode)? {
                if v.fract() == 0.0 && v >= 1.0 && v < f64::from(white) {
                    if v < f64::from(max_sample) {
                        // A saturation level samples exceed is not where
                        // this frame clips: white stays full scale, and the
                        // frame is refused unless --white settles it.
                        let above = data.iter().filter(|&&x| f64::from(x) > v).count();
                        white_conflict = Some(format!(
                            "{key} = {v} lies below {above} of the {n} samples (the largest is {max_sample}): the header's saturation level contradicts the data; --white sets the level to use ({v} clips the samples above it, {white} is full scale)"
                        ));
                    } else {
                        white = v as u32;
                    }
                    break;
                }
            }
        }
    }

    Ok(FitsImage {
        width,
        height,
        data,
        bayer,
        row_order,
        bitpix,
        white,
        exposure_s: exposure.map(|(_, t)| t),
        egain_e_per_adu,
        gain_setting,
        temperature_c: temperature.map(|(_, t)| t as f32),
        iso,
        instrument,
        date_obs,
        binning,
        conversion,
        white_conflict,
    })
}

/// Why the pixels cannot be used: damaged (NaN, BLANK) or of a kind pgrf
/// does not handle (calibrated, out of range).
enum Refusal {
    Decode(String),
    Unsupported(String),
}

/// Integer samples: physical = BZERO + BSCALE * stored must be an integer
/// in 0..=65535.
fn integers(
    stored: impl Iterator<Item = i64>,
    n: usize,
    bitpix: i32,
    bzero: f64,
    bscale: f64,
    blank: Option<i64>,
) -> std::result::Result<(Vec<u16>, Option<String>), Refusal> {
    // The common case (BZERO an integer, BSCALE 1) in exact integer arithmetic.
    let exact_offset =
        (bscale == 1.0 && bzero.fract() == 0.0 && bzero.abs() < 1e18).then_some(bzero as i128);
    let mut out = Vec::with_capacity(n);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut blanks, mut fractional) = (0usize, 0usize);
    for s in stored.take(n) {
        if Some(s) == blank {
            blanks += 1;
            out.push(0);
            continue;
        }
        let v = match exact_offset {
            Some(z) => {
                let p = i128::from(s) + z;
                lo = lo.min(p as f64);
                hi = hi.max(p as f64);
                p
            }
            None => {
                let p = bzero + bscale * s as f64;
                lo = lo.min(p);
                hi = hi.max(p);
                let r = p.round();
                if (p - r).abs() > 1e-6 {
                    fractional += 1;
                }
                r as i128
            }
        };
        out.push(u16::try_from(v).unwrap_or(0));
    }
    if out.len() != n {
        return Err(Refusal::Decode(format!(
            "truncated: the image has {} of its {n} samples",
            out.len()
        )));
    }
    if blanks > 0 {
        return Err(Refusal::Decode(format!(
            "{blanks} samples equal BLANK = {} (undefined pixels); pgrf needs every pixel",
            blank.unwrap_or(0)
        )));
    }
    let scaled = if bzero != 0.0 || bscale != 1.0 {
        " after BZERO/BSCALE"
    } else {
        ""
    };
    if fractional > 0 {
        return Err(Refusal::Unsupported(format!(
            "{fractional} BITPIX {bitpix} samples are not integers{scaled} \
             (BZERO = {bzero}, BSCALE = {bscale}); pgrf needs integer ADU"
        )));
    }
    if lo < 0.0 || hi > 65535.0 {
        return Err(Refusal::Unsupported(format!(
            "BITPIX {bitpix} values span {lo}..{hi}{scaled}; pgrf needs ADU in 0..65535{}",
            if lo < 0.0 {
                " (negative values: a calibrated frame, or signed data without BZERO = 32768?)"
            } else {
                ""
            }
        )));
    }
    let conversion = match bitpix {
        16 if bscale == 1.0 => None,
        16 => Some(format!(
            "BITPIX 16 scaled by BZERO = {bzero}, BSCALE = {bscale}"
        )),
        8 => Some(format!("BITPIX 8 widened to 16 bits{scaled}")),
        _ => Some(format!(
            "BITPIX {bitpix} integers{scaled}, all within 0..65535"
        )),
    };
    Ok((out, conversion))
}

/// Floating-point samples: no NaN or infinity; normalised 0..1 data (Siril,
/// PixInsight) are scaled by 65535, 0..65535 data rounded, anything else
/// (negative: a calibrated frame) refused.
fn floats<T: Copy + Into<f64>>(
    stored: impl Iterator<Item = T>,
    n: usize,
    bitpix: i32,
    bzero: f64,
    bscale: f64,
) -> std::result::Result<(Vec<u16>, Option<String>), Refusal> {
    // Kept in the stored type (at most the file's own size) for the second
    // pass once the range is known.
    let values: Vec<T> = stored.take(n).collect();
    if values.len() != n {
        return Err(Refusal::Decode(format!(
            "truncated: the image has {} of its {n} samples",
            values.len()
        )));
    }
    let physical = |v: T| bzero + bscale * v.into();
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut nan, mut inf) = (0usize, 0usize);
    for &v in &values {
        let p = physical(v);
        if p.is_nan() {
            nan += 1;
        } else if p.is_infinite() {
            inf += 1;
        } else {
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    if nan + inf > 0 {
        return Err(Refusal::Decode(format!(
            "{nan} NaN and {inf} infinite samples of {n} (BITPIX {bitpix}); \
             pgrf needs a value for every pixel"
        )));
    }
    let (scale, conversion) = if lo >= 0.0 && hi <= 1.0 {
        (65535.0, format!("BITPIX {bitpix} in 0..1 scaled by 65535"))
    } else if lo >= 0.0 && hi <= 65535.0 {
        (
            1.0,
            format!("BITPIX {bitpix} in 0..65535 rounded to integers"),
        )
    } else {
        return Err(Refusal::Unsupported(format!(
            "BITPIX {bitpix} values span {lo}..{hi}: neither normalised 0..1 nor ADU 0..65535{}; \
             pgrf needs the camera's raw frame",
            if lo < 0.0 {
                " (negative values: probably a calibrated frame)"
            } else {
                ""
            }
        )));
    };
    let data = values
        .into_iter()
        .map(|v| (physical(v) * scale).round().clamp(0.0, 65535.0) as u16)
        .collect();
    Ok((data, Some(conversion)))
}

/// ROWORDER: TOP-DOWN or BOTTOM-UP (any case), `None` when absent; any
/// other value is refused, since what pgrf writes from the frame states it.
fn row_order(header: &ValueMap) -> std::result::Result<Option<RowOrder>, String> {
    match string(header, "ROWORDER")? {
        None => Ok(None),
        Some(r) => match r.to_ascii_uppercase().as_str() {
            "TOP-DOWN" => Ok(Some(RowOrder::TopDown)),
            "BOTTOM-UP" => Ok(Some(RowOrder::BottomUp)),
            other => Err(format!(
                "ROWORDER = '{other}' is neither TOP-DOWN nor BOTTOM-UP"
            )),
        },
    }
}

/// The phase of `data[0]` from BAYERPAT, XBAYROFF, YBAYROFF and ROWORDER
/// (`rows`, module documentation).
fn bayer_phase(
    name: &Path,
    header: &ValueMap,
    height: usize,
    rows: Option<RowOrder>,
) -> Result<Option<Cfa>> {
    let no_phase = || {
        RawError::unsupported(
            name,
            "BAYERPAT = T says the sensor has a colour filter but not its phase; \
             pgrf needs RGGB, BGGR, GRBG or GBRG",
        )
    };
    let pattern = match header.get("BAYERPAT") {
        None | Some(Value::Undefined) | Some(Value::Logical { value: false, .. }) => {
            return Ok(None)
        }
        Some(Value::Logical { value: true, .. }) => return Err(no_phase()),
        Some(Value::String { value, .. }) => {
            let v = value.trim().to_ascii_uppercase();
            if v.is_empty() {
                return Ok(None);
            }
            if v == "TRUE" || v == "T" {
                return Err(no_phase());
            }
            v.parse::<Cfa>().map_err(|_| {
                RawError::unsupported(
                    name,
                    format!("BAYERPAT = '{v}' is not a 2x2 Bayer phase (RGGB, BGGR, GRBG or GBRG)"),
                )
            })?
        }
        Some(other) => {
            return Err(RawError::decode(
                name,
                format!("BAYERPAT = {} is not a Bayer pattern name", show(other)),
            ))
        }
    };
    let dec = |m: String| RawError::decode(name, m);
    let xoff = integer(header, "XBAYROFF").map_err(dec)?.unwrap_or(0);
    let yoff = integer(header, "YBAYROFF").map_err(dec)?.unwrap_or(0);
    let bottom_up = rows == Some(RowOrder::BottomUp);
    Ok(Some(stored_phase(pattern, xoff, yoff, bottom_up, height)))
}

/// BAYERPAT (top-down convention) to the phase of stored row 0, column 0.
pub(crate) fn stored_phase(
    pattern: Cfa,
    xoff: i64,
    yoff: i64,
    bottom_up: bool,
    height: usize,
) -> Cfa {
    let flip = if bottom_up { (height + 1) % 2 } else { 0 }; // (H - 1) mod 2
    let dy = (yoff.rem_euclid(2) as usize + flip) % 2;
    let dx = xoff.rem_euclid(2) as usize;
    pattern.shifted(dy, dx)
}

/// A numeric keyword (integer, real, or a string holding a number).
fn number(header: &ValueMap, key: &str) -> std::result::Result<Option<f64>, String> {
    let v = match header.get(key) {
        None | Some(Value::Undefined) => return Ok(None),
        Some(Value::Integer { value, .. }) => *value as f64,
        Some(Value::Float { value, .. }) => *value,
        Some(Value::String { value, .. }) => {
            let t = value.trim();
            if t.is_empty() {
                return Ok(None);
            }
            t.parse::<f64>()
                .map_err(|_| format!("{key} = '{t}' is not a number"))?
        }
        Some(other) => return Err(format!("{key} = {} is not a number", show(other))),
    };
    if !v.is_finite() {
        return Err(format!("{key} = {v} is not a finite number"));
    }
    Ok(Some(v))
}

/// An integer keyword (a real with no fraction is accepted).
/// XBINNING and YBINNING (1 to 64 each; an absent one is 1), None when
/// the header states neither.
fn binning(header: &ValueMap) -> std::result::Result<Option<(u32, u32)>, String> {
    let axis = |key: &str| -> std::result::Result<Option<u32>, String> {
        match integer(header, key)? {
            None => Ok(None),
            Some(v) if (1..=64).contains(&v) => Ok(Some(v as u32)),
            Some(v) => Err(format!("{key} = {v} is not a binning factor (1 to 64)")),
        }
    };
    Ok(match (axis("XBINNING")?, axis("YBINNING")?) {
        (None, None) => None,
        (x, y) => Some((x.unwrap_or(1), y.unwrap_or(1))),
    })
}

fn integer(header: &ValueMap, key: &str) -> std::result::Result<Option<i64>, String> {
    match header.get(key) {
        Some(Value::Integer { value, .. }) => Ok(Some(*value)),
        _ => match number(header, key)? {
            None => Ok(None),
            Some(v) if v.fract() == 0.0 && v.abs() < 9e15 => Ok(Some(v as i64)),
            Some(v) => Err(format!("{key} = {v} is not an integer")),
        },
    }
}

/// A string keyword, trimmed; blank reads as absent.
fn string(header: &ValueMap, key: &str) -> std::result::Result<Option<String>, String> {
    match header.get(key) {
        None | Some(Value::Undefined) => Ok(None),
        Some(Value::String { value, .. }) => {
            let t = value.trim();
            Ok((!t.is_empty()).then(|| t.to_string()))
        }
        Some(other) => Err(format!("{key} = {} is not a string", show(other))),
    }
}

/// A header value as the file wrote it, for messages.
fn show(v: &Value) -> String {
    match v {
        Value::Integer { value, .. } => value.to_string(),
        Value::Float { value, .. } => value.to_string(),
        Value::Logical { value, .. } => if *value { "T" } else { "F" }.to_string(),
        Value::String { value, .. } => format!("'{value}'"),
        Value::Undefined => "(blank)".to_string(),
        Value::Invalid(s) => format!("'{}'", s.trim()),
    }
}

/// Turn a fitsrs header error into a message naming what is wrong, looking
/// at the mandatory cards ourselves where fitsrs's words do not.
fn header_error(bytes: &[u8], e: &fitsrs::error::Error) -> String {
    use fitsrs::error::Error;
    match e {
        Error::Io(std::io::ErrorKind::UnexpectedEof) => {
            return "the header has no END card before the end of the file (truncated?)".into()
        }
        Error::StaticError("EOF reached") => {
            return "truncated: the file ends inside the header's 2880-byte block".into()
        }
        _ => {}
    }
    let cards = raw_cards(bytes, 0);
    let get = |key: &str| cards.iter().find(|(k, _)| *k == key).map(|(_, v)| *v);
    match get("BITPIX") {
        None => return "the mandatory BITPIX card is missing".into(),
        Some(Some(b)) if ["8", "16", "32", "64", "-32", "-64"].contains(&b) => {}
        Some(b) => {
            return format!(
                "BITPIX = {} is not a FITS sample type (8, 16, 32, 64, -32 or -64)",
                b.unwrap_or("(blank)")
            )
        }
    }
    let naxis = match get("NAXIS") {
        Some(Some(v)) => match v.parse::<u64>() {
            Ok(n) if n <= 999 => n,
            _ => return format!("NAXIS = {v} is not an axis count (0..=999)"),
        },
        _ => return "the mandatory NAXIS card is missing or blank".into(),
    };
    for i in 1..=naxis {
        let key = format!("NAXIS{i}");
        match get(&key) {
            Some(Some(v)) if v.parse::<u64>().is_ok() => {}
            Some(Some(v)) => return format!("{key} = {v} is not an axis length"),
            _ => return format!("{key} is missing (NAXIS = {naxis})"),
        }
    }
    format!("cannot parse the primary header: {e}")
}

/// An axis length that pgrf refuses whatever the rest of the header says:
/// NAXIS1 or NAXIS2 outside 2..=65536, or a further axis above 65536.
fn oversized_axis(bytes: &[u8]) -> Option<String> {
    raw_cards(bytes, 0).into_iter().find_map(|(key, value)| {
        let axis: u32 = key.strip_prefix("NAXIS")?.parse().ok()?;
        let v: i128 = value?.parse().ok()?;
        match axis {
            1 | 2 if !(2..=i128::from(MAX_SIDE)).contains(&v) => {
                Some(format!("{key} = {v} is outside 2..={MAX_SIDE} pixels"))
            }
            3.. if v > i128::from(MAX_SIDE) => Some(format!(
                "{key} = {v}: a cube of that many planes; pgrf reads one 2-D frame"
            )),
            _ => None,
        }
    })
}

/// Why a primary HDU without an image cannot be read; a tile-compressed
/// (fpack) file is recognised from its first extension's header, scanned
/// here without fitsrs so that none of its values sizes a buffer.
fn empty_primary(name: &Path, bytes: &[u8], next_header: usize) -> RawError {
    let cards = raw_cards(bytes, next_header);
    let get = |key: &str| cards.iter().find(|(k, _)| *k == key).and_then(|(_, v)| *v);
    match get("XTENSION") {
        None => RawError::decode(
            name,
            "the primary HDU holds no image (NAXIS = 0) and no extension follows",
        ),
        Some(x) if x.trim_matches('\'').trim() == "BINTABLE" && get("ZIMAGE") == Some("T") => {
            RawError::unsupported(
                name,
                "tile-compressed (fpack) image: the primary HDU is empty and the image is in a \
                 compressed binary-table extension; decompress it first with funpack",
            )
        }
        Some(x) => RawError::unsupported(
            name,
            format!(
                "the primary HDU holds no image (NAXIS = 0); pgrf reads only the primary image, \
                 and the first extension is XTENSION = {x}"
            ),
        ),
    }
}

/// The (keyword, value field) of the cards from `start` up to END or the end
/// of the file, at most 100 blocks: a bounded look at a header for messages.
fn raw_cards(bytes: &[u8], start: usize) -> Vec<(&str, Option<&str>)> {
    let Some(rest) = bytes.get(start..) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for card in rest.chunks_exact(CARD).take(100 * BLOCK / CARD) {
        let key = std::str::from_utf8(&card[..8]).unwrap_or("").trim_end();
        if key == "END" {
            break;
        }
        out.push((key, value_field(card)));
    }
    out
}

/// The value of a `KEY     = value / comment` card, trimmed; `None` when the
/// card has no value indicator or a blank value.
fn value_field(card: &[u8]) -> Option<&str> {
    if card.len() < 10 || &card[8..10] != b"= " {
        return None;
    }
    let text = std::str::from_utf8(&card[10..]).ok()?;
    let value = if text.trim_start().starts_with('\'') {
        // A string: up to its closing quote ('' is an escaped quote).
        let t = text.trim_start();
        let mut end = None;
        let b = t.as_bytes();
        let mut i = 1;
        while i < b.len() {
            if b[i] == b'\'' {
                if b.get(i + 1) == Some(&b'\'') {
                    i += 2;
                    continue;
                }
                end = Some(i + 1);
                break;
            }
            i += 1;
        }
        &t[..end.unwrap_or(t.len())]
    } else {
        text.split('/').next().unwrap_or("")
    };
    let value = value.trim();
    (!value.is_empty()).then_some(value)
}

// ---------------------------------------------------------------- writing

/// `len` rounded up to whole 2880-byte blocks.
fn padded(len: usize) -> usize {
    len.div_ceil(BLOCK) * BLOCK
}

/// How many bytes of `header` (whole cards, ending with END and padded
/// with spaces) lie from the start of its END card on: what to cut to
/// append cards before a new END.
fn padding_after_end(header: &[u8]) -> usize {
    let end = header
        .chunks(CARD)
        .rposition(|c| c.starts_with(b"END "))
        .expect("header() writes END");
    header.len() - end * CARD
}

fn check_geometry(width: usize, height: usize, len: usize) -> Result<()> {
    if width == 0 || height == 0 {
        return Err(RawError::FitsEmpty { width, height });
    }
    if width.checked_mul(height) != Some(len) {
        return Err(RawError::SampleCount {
            samples: len,
            width,
            height,
        });
    }
    Ok(())
}

/// Keywords the encoders write themselves or that are not plain value cards.
fn reserved(key: &str) -> bool {
    matches!(
        key,
        "SIMPLE"
            | "BITPIX"
            | "NAXIS"
            | "EXTEND"
            | "BZERO"
            | "BSCALE"
            | "BLANK"
            | "END"
            | "COMMENT"
            | "HISTORY"
            | "CONTINUE"
            | "HIERARCH"
            | "XTENSION"
            | "PCOUNT"
            | "GCOUNT"
            | "GROUPS"
    ) || (key.starts_with("NAXIS") && key[5..].bytes().all(|b| b.is_ascii_digit()))
}

/// The header: mandatory cards, `fixed` (the encoder's own), the caller's
/// cards, END, padded with spaces to whole blocks.
fn header(
    bitpix: i32,
    width: usize,
    height: usize,
    fixed: &[FitsCard],
    cards: &[FitsCard],
) -> Result<Vec<u8>> {
    let mandatory = [
        FitsCard::new(
            "SIMPLE",
            FitsValue::Bool(true),
            "file does conform to FITS standard",
        ),
        FitsCard::new(
            "BITPIX",
            FitsValue::Int(i64::from(bitpix)),
            "number of bits per data pixel",
        ),
        FitsCard::new("NAXIS", FitsValue::Int(2), "number of data axes"),
        FitsCard::new(
            "NAXIS1",
            FitsValue::Int(width as i64),
            "length of data axis 1",
        ),
        FitsCard::new(
            "NAXIS2",
            FitsValue::Int(height as i64),
            "length of data axis 2",
        ),
    ];
    let mut seen = std::collections::HashSet::new();
    for c in cards {
        if reserved(&c.key) {
            return Err(RawError::FitsReservedKey { key: c.key.clone() });
        }
        if !seen.insert(c.key.as_str()) {
            return Err(RawError::FitsDuplicateKey { key: c.key.clone() });
        }
    }
    let mut out = Vec::with_capacity(BLOCK);
    for c in mandatory.iter().chain(fixed).chain(cards) {
        out.extend_from_slice(format_card(c)?.as_bytes());
    }
    out.extend_from_slice(format!("{:<80}", "END").as_bytes());
    out.resize(padded(out.len()), b' ');
    Ok(out)
}

/// One 80-character card in the FITS fixed format.
fn format_card(c: &FitsCard) -> Result<String> {
    let bad = |reason: String| RawError::FitsCard {
        key: c.key.clone(),
        reason,
    };
    if c.key.is_empty()
        || c.key.len() > 8
        || !c
            .key
            .bytes()
            .all(|b| b.is_ascii_uppercase() || b.is_ascii_digit() || b == b'-' || b == b'_')
    {
        return Err(bad(
            "a keyword is 1 to 8 characters of A-Z, 0-9, '-' and '_'".into(),
        ));
    }
    let printable = |s: &str| s.bytes().all(|b| (0x20..=0x7e).contains(&b));
    let value = match &c.value {
        FitsValue::Int(v) => format!("{v:>20}"),
        FitsValue::Float(v) => {
            if !v.is_finite() {
                return Err(bad(format!("{v} is not a finite number")));
            }
            format!("{:>20}", format_real(*v))
        }
        FitsValue::Bool(b) => format!("{:>20}", if *b { "T" } else { "F" }),
        FitsValue::Str(s) => {
            if !printable(s) {
                return Err(bad("strings must be printable ASCII".into()));
            }
            // Quotes doubled; padded to 8 characters as the standard's
            // fixed format (closing quote in column 20 or later) asks.
            format!("'{:<8}'", s.replace('\'', "''"))
        }
    };
    if !printable(&c.comment) {
        return Err(bad("the comment must be printable ASCII".into()));
    }
    let mut card = format!("{:<8}= {value}", c.key);
    if !c.comment.is_empty() {
        card.push_str(" / ");
        card.push_str(&c.comment);
    }
    if card.len() > CARD {
        return Err(bad(format!(
            "{} characters do not fit in one 80-character card; shorten the value or comment",
            card.len()
        )));
    }
    Ok(format!("{card:<80}"))
}

/// The shortest text that reads back as `v`, in at most 20 characters, with
/// a decimal point so no reader takes it for an integer; past 20 characters
/// (only for extreme exponents) the precision is cut to fit, as astropy does.
fn format_real(v: f64) -> String {
    let shortest = with_point(&format!("{v:?}").replace('e', "E"));
    if shortest.len() <= 20 {
        return shortest;
    }
    // Rounding up can overflow past f64::MAX: keep the first that reads back finite.
    (0..=16)
        .rev()
        .map(|p| with_point(&format!("{v:.p$E}")))
        .find(|s| s.len() <= 20 && s.parse::<f64>().is_ok_and(f64::is_finite))
        .unwrap_or_else(|| with_point(&format!("{v:.0E}")))
}

/// "1E20" -> "1.0E20"; strings with a '.' are returned unchanged.
fn with_point(s: &str) -> String {
    if s.contains('.') {
        return s.to_string();
    }
    match s.find('E') {
        Some(i) => format!("{}.0{}", &s[..i], &s[i..]),
        None => format!("{s}.0"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cards_are_in_fixed_format() {
        let card = |k: &str, v: FitsValue, c: &str| format_card(&FitsCard::new(k, v, c)).unwrap();
        let c = card("EXPTIME", FitsValue::Float(30.0), "seconds");
        assert_eq!(c.len(), 80);
        assert_eq!(&c[..30], "EXPTIME =                 30.0");
        assert_eq!(c[30..].trim_end(), " / seconds");
        let c = card("XBAYROFF", FitsValue::Int(-1), "");
        assert_eq!(c.trim_end(), "XBAYROFF=                   -1");
        let c = card("SIMPLE", FitsValue::Bool(true), "");
        assert_eq!(&c[29..30], "T");
        let c = card("INSTRUME", FitsValue::Str("ZWO 'ASI' 294".into()), "");
        assert_eq!(c.trim_end(), "INSTRUME= 'ZWO ''ASI'' 294'");
        let c = card("BAYERPAT", FitsValue::Str("RGGB".into()), "");
        assert_eq!(c.trim_end(), "BAYERPAT= 'RGGB    '");
    }

    #[test]
    fn bad_cards_are_refused() {
        let try_card = |k: &str, v: FitsValue, c: &str| format_card(&FitsCard::new(k, v, c));
        assert!(try_card("exptime", FitsValue::Int(1), "").is_err());
        assert!(try_card("TOOLONGKEY", FitsValue::Int(1), "").is_err());
        assert!(try_card("A B", FitsValue::Int(1), "").is_err());
        assert!(try_card("", FitsValue::Int(1), "").is_err());
        assert!(try_card("X", FitsValue::Float(f64::NAN), "").is_err());
        assert!(try_card("X", FitsValue::Float(f64::INFINITY), "").is_err());
        assert!(try_card("X", FitsValue::Str("é".into()), "").is_err());
        assert!(try_card("X", FitsValue::Str("a\tb".into()), "").is_err());
        assert!(try_card("X", FitsValue::Str("x".repeat(69)), "").is_err());
        assert!(try_card("X", FitsValue::Str("x".repeat(68)), "").is_ok());
        assert!(try_card("X", FitsValue::Int(1), &"c".repeat(60)).is_err());
        assert!(try_card("DATE-OBS", FitsValue::Int(1), "").is_ok());
        assert!(try_card("CCD_TEMP", FitsValue::Int(1), "").is_ok());
    }

    #[test]
    fn reals_read_back_exactly_and_fit() {
        for v in [
            0.0,
            -0.0,
            1.0,
            0.1,
            -12.5,
            1e-7,
            1e20,
            123456.789,
            6.02214076e23,
            -1.5e-300,
            f64::MAX,
            f64::MIN_POSITIVE,
            1.2345678901234567e-300,
        ] {
            let s = format_real(v);
            assert!(s.len() <= 20, "{s}");
            assert!(s.contains('.'), "{s}");
            let back: f64 = s.parse().unwrap();
            if with_point(&format!("{v:?}")).len() <= 20 {
                assert_eq!(back.to_bits(), v.to_bits(), "{s}");
            } else {
                assert!(((back - v) / v).abs() < 1e-12, "{s}");
            }
        }
    }

    #[test]
    fn reserved_keywords() {
        for k in [
            "SIMPLE", "NAXIS", "NAXIS3", "BZERO", "END", "COMMENT", "BLANK",
        ] {
            assert!(reserved(k), "{k}");
        }
        for k in ["NAXISX", "EXPTIME", "BAYERPAT"] {
            assert!(!reserved(k), "{k}");
        }
    }

    #[test]
    fn stored_phase_follows_siril() {
        // Siril's adjust_Bayer_pattern_offset: odd XBAYROFF RGGB->GRBG,
        // BGGR->GBRG, GBRG->BGGR, GRBG->RGGB; odd YBAYROFF RGGB->GBRG,
        // BGGR->GRBG, GBRG->RGGB, GRBG->BGGR.
        let x = [
            (Cfa::Rggb, Cfa::Grbg),
            (Cfa::Bggr, Cfa::Gbrg),
            (Cfa::Gbrg, Cfa::Bggr),
            (Cfa::Grbg, Cfa::Rggb),
        ];
        for (from, to) in x {
            assert_eq!(stored_phase(from, 1, 0, false, 100), to);
            assert_eq!(stored_phase(from, -1, 0, false, 100), to);
            assert_eq!(stored_phase(from, 2, 0, false, 100), from);
        }
        let y = [
            (Cfa::Rggb, Cfa::Gbrg),
            (Cfa::Bggr, Cfa::Grbg),
            (Cfa::Gbrg, Cfa::Rggb),
            (Cfa::Grbg, Cfa::Bggr),
        ];
        for (from, to) in y {
            assert_eq!(stored_phase(from, 0, 1, false, 100), to);
            // Siril's adjust_Bayer_pattern_orientation: BOTTOM-UP with an
            // even height flips the 2x2 rows, with an odd height it does not.
            assert_eq!(stored_phase(from, 0, 0, true, 100), to);
            assert_eq!(stored_phase(from, 0, 0, true, 101), from);
            // Flip then odd YBAYROFF: two row swaps cancel.
            assert_eq!(stored_phase(from, 0, 1, true, 100), from);
        }
    }

    #[test]
    fn value_field_reads_strings_and_numbers() {
        let card = |s: &str| format!("{s:<80}").into_bytes();
        assert_eq!(
            value_field(&card("BITPIX  =                   16 / x")),
            Some("16")
        );
        assert_eq!(
            value_field(&card("XTENSION= 'BINTABLE'  / x")),
            Some("'BINTABLE'")
        );
        assert_eq!(
            value_field(&card("A       = 'it''s / here' / c")),
            Some("'it''s / here'")
        );
        assert_eq!(value_field(&card("COMMENT hello")), None);
        assert_eq!(value_field(&card("A       =    / c")), None);
        assert!(is_fits(&card("SIMPLE  =                    T / conforms")));
        assert!(!is_fits(&card("SIMPLE  =                    F")));
        assert!(!is_fits(b"SIMPLE  = T"));
    }
}
