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

mod keyword;
mod read;
#[cfg(test)]
mod tests;
mod write;

pub use keyword::KeywordError;
pub(crate) use read::stored_phase;
pub use read::{fits_temperature, is_fits, read_fits, read_fits_samples};
pub use write::{card_text, encode_fits_f32, encode_fits_f32_history, encode_fits_u16};

use crate::cfa::Cfa;
use serde::Serialize;

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
    /// IMAGETYP: "Light Frame", "Dark Frame", "Flat Field", "Bias Frame"
    /// (CCDSoft, MaxIm DL), "LIGHT", ... as written.
    pub image_type: Option<String>,
    /// FILTER: the filter the frame was taken through.
    pub filter: Option<String>,
    /// OBJECT: what was observed.
    pub object: Option<String>,
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
    /// IMAGETYP, as written.
    pub image_type: Option<String>,
    /// FILTER, as written.
    pub filter: Option<String>,
    /// OBJECT, as written.
    pub object: Option<String>,
    /// ROWORDER as the header states it; `None` without one.
    pub row_order: Option<RowOrder>,
    /// XBINNING x YBINNING, when the header states either: masters and
    /// lights must be binned alike.
    pub binning: Option<(u32, u32)>,
    /// How samples that were not unsigned 16-bit integers became DN.
    pub conversion: Option<String>,
}

impl FitsHeader {
    /// The IMAGETYP of a calibration frame (bias, dark, flat, or a master
    /// of one; CCDSoft's "Bias Frame", "Dark Frame", "Flat Field", IRAF's
    /// "zero", ...), None for a light or a frame that does not say.
    pub fn calibration_type(&self) -> Option<&str> {
        let t = self.image_type.as_deref()?;
        let lower = t.to_ascii_lowercase();
        ["bias", "dark", "flat", "zero", "offset", "master"]
            .iter()
            .any(|k| lower.contains(k))
            .then_some(t)
    }
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
