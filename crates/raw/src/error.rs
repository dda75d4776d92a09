//! One error type for everything the RAW layer can refuse.
//!
//! Every variant renders as a single line that names the file (where there is
//! one) and says what was wrong, because the CLI prints it verbatim and scripts
//! grep it.

use std::path::{Path, PathBuf};

/// Why a RAW file could not be read, packed or written.
#[derive(Debug, thiserror::Error)]
pub enum RawError {
    /// The file could not be opened or read. The operating system's error
    /// is part of the message and not a separate `source`, so that error
    /// chains print it once.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        error: std::io::Error,
    },
    /// The file is damaged, truncated, not a RAW file, or its metadata gives
    /// unusable levels.
    #[error("{path}: cannot decode: {reason}")]
    Decode {
        /// The file.
        path: PathBuf,
        /// The decoder's complaint, on one line.
        reason: String,
    },
    /// The file's structure is refused before decoding: cut short,
    /// malformed or contradicting itself ([`crate::container::Cause`] says
    /// which, for callers that act on it).
    #[error("{path}: cannot decode: {source}")]
    Container {
        /// The file.
        path: PathBuf,
        /// What is wrong with its structure.
        source: crate::container::ContainerError,
    },
    /// A FITS header card whose value pgrf cannot use; the
    /// [`crate::fits::KeywordError`] names the keyword, for callers that
    /// point the user at it.
    #[error("{}: cannot decode: {}", path.display(), one_line(error.to_string()))]
    FitsKeyword {
        /// The file.
        path: PathBuf,
        /// The card and what is wrong with its value.
        error: crate::fits::KeywordError,
    },
    /// A readable file of a kind pgrf does not handle: linear (demosaiced) or
    /// monochrome data, X-Trans, floating-point samples.
    #[error("{path}: unsupported: {reason}")]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// What about it pgrf cannot handle, on one line.
        reason: String,
    },
    /// A frame (or one stage's work on it) that the memory available cannot
    /// hold, refused before the allocation that would abort the process.
    #[error("{path}: {reason}")]
    Memory {
        /// The file.
        path: PathBuf,
        /// What needs how much, and how much there is, on one line.
        reason: String,
    },
    /// A frame with no pixels.
    #[error("invalid input: empty frame {width}x{height}")]
    EmptyFrame {
        /// Width given, pixels.
        width: usize,
        /// Height given, pixels.
        height: usize,
    },
    /// Samples for a new frame that are not `width * height` of them.
    #[error("invalid input: mosaic has {samples} samples, {width}x{height} needs {needed}")]
    MosaicSize {
        /// Samples given.
        samples: usize,
        /// Width given, pixels.
        width: usize,
        /// Height given, pixels.
        height: usize,
        /// `width * height`.
        needed: usize,
    },
    /// New pixel data for a frame that holds a different number of samples.
    #[error("invalid input: new mosaic has {samples} samples, frame has {expected}")]
    MosaicReplaced {
        /// Samples given.
        samples: usize,
        /// Samples of the frame.
        expected: usize,
    },
    /// A frame whose mosaic length disagrees with its own width and height
    /// (its public fields were changed apart).
    #[error("invalid input: frame mosaic length does not match its size")]
    MosaicInconsistent,
    /// A monochrome frame given to something that needs a colour filter
    /// array; `what` names that ("the SPC denoiser").
    #[error(
        "invalid input: a monochrome frame (no colour filter array); {what} requires a Bayer CFA mosaic"
    )]
    NeedsCfa {
        /// What requires the CFA.
        what: String,
    },
    /// A black level that is negative or not a number.
    #[error(
        "invalid input: black level of plane {plane} is {black}; it must be a finite value >= 0"
    )]
    BadBlack {
        /// The plane (R, G1, B, G2).
        plane: &'static str,
        /// Its black level, DN.
        black: f32,
    },
    /// A black level at or above the white level.
    #[error(
        "invalid input: black level {black} of plane {plane} is not below the white level {white}"
    )]
    BlackNotBelowWhite {
        /// The plane (R, G1, B, G2).
        plane: &'static str,
        /// Its black level, DN.
        black: f32,
        /// The white level, DN.
        white: u32,
    },
    /// A white level above 65535.
    #[error("invalid input: white level {white} exceeds the 16-bit range")]
    WhiteTooHigh {
        /// The white level, DN.
        white: u32,
    },
    /// Black levels given as neither one value nor four.
    #[error("invalid input: black level needs 1 or 4 values (R,G1,B,G2), got {count}")]
    BlackCount {
        /// How many were given.
        count: usize,
    },
    /// A crop with an odd offset or size, which would split CFA cells.
    #[error(
        "invalid input: crop {width}x{height} at ({row}, {col}): offsets and sizes must be even (whole CFA cells)"
    )]
    CropOdd {
        /// Top row of the window.
        row: usize,
        /// Left column of the window.
        col: usize,
        /// Height of the window.
        height: usize,
        /// Width of the window.
        width: usize,
    },
    /// A crop that is empty or reaches past the frame.
    #[error(
        "invalid input: crop {width}x{height} at ({row}, {col}) is not inside the {frame_width}x{frame_height} frame"
    )]
    CropOutside {
        /// Top row of the window.
        row: usize,
        /// Left column of the window.
        col: usize,
        /// Height of the window.
        height: usize,
        /// Width of the window.
        width: usize,
        /// The frame's width.
        frame_width: usize,
        /// The frame's height.
        frame_height: usize,
    },
    /// A frame with no complete 2x2 cell to pack.
    #[error(
        "invalid input: frame {width}x{height} is too small to pack (needs at least one 2x2 cell)"
    )]
    TooSmallToPack {
        /// The frame's width.
        width: usize,
        /// The frame's height.
        height: usize,
    },
    /// A packed array whose shape is not the one the frame packs to.
    #[error(
        "invalid input: packed array has shape {shape:?}, frame {width}x{height} packs to [4, {packed_height}, {packed_width}]"
    )]
    PackedShape {
        /// The array's shape.
        shape: Vec<usize>,
        /// The frame's width.
        width: usize,
        /// The frame's height.
        height: usize,
        /// Rows of each packed plane.
        packed_height: usize,
        /// Columns of each packed plane.
        packed_width: usize,
    },
    /// A packed array holding NaN, which has no DN to write.
    #[error("invalid input: packed image contains NaN (first at flat index {index})")]
    PackedNan {
        /// Flat index of the first NaN.
        index: usize,
    },
    /// A frame too wide or tall for DNG's 16-bit active-area tag.
    #[error("invalid input: frame {width}x{height} is too large for a DNG active-area tag")]
    TooLargeForDng {
        /// The frame's width.
        width: usize,
        /// The frame's height.
        height: usize,
    },
    /// An encoder that failed on data it was given; `format` names it
    /// ("DNG", "PNG").
    #[error("invalid input: {format} encoding failed: {reason}")]
    Encode {
        /// The file format being encoded.
        format: &'static str,
        /// The encoder's complaint.
        reason: String,
    },
    /// A PNG bit depth other than 8 or 16.
    #[error("invalid input: PNG bit depth must be 8 or 16, got {bits}")]
    PngBits {
        /// The depth asked for.
        bits: u8,
    },
    /// A preview gain that is not a positive number.
    #[error("invalid input: preview gain must be a positive number, got {gain}")]
    BadGain {
        /// The gain given.
        gain: f32,
    },
    /// A headerless dump's bit depth outside 1..=16.
    #[error("invalid input: bit depth {bits} is outside 1..=16")]
    BadBits {
        /// The depth given.
        bits: u32,
    },
    /// A headerless dump's size whose byte count overflows.
    #[error("invalid input: frame size overflows")]
    SizeOverflow {
        /// Width given, pixels.
        width: usize,
        /// Height given, pixels.
        height: usize,
    },
    /// An image to encode as FITS with a side of 0.
    #[error("invalid input: FITS image of {width}x{height} pixels: both sides must be at least 1")]
    FitsEmpty {
        /// Width given, pixels.
        width: usize,
        /// Height given, pixels.
        height: usize,
    },
    /// Samples to encode that are not `width * height` of them.
    #[error("invalid input: {samples} samples do not make a {width}x{height} image")]
    SampleCount {
        /// Samples given.
        samples: usize,
        /// Width given, pixels.
        width: usize,
        /// Height given, pixels.
        height: usize,
    },
    /// A FITS master with NaN or infinite values.
    #[error(
        "invalid input: {bad} of {samples} samples are NaN or infinite; a FITS master must hold finite values"
    )]
    NonFiniteMaster {
        /// How many are not finite.
        bad: usize,
        /// Samples in all.
        samples: usize,
    },
    /// A master whose value count does not match its template frame.
    #[error("invalid input: master has {values} values, a {width}x{height} frame needs {needed}")]
    MasterSize {
        /// Values given.
        values: usize,
        /// The template's width.
        width: usize,
        /// The template's height.
        height: usize,
        /// `width * height`.
        needed: usize,
    },
    /// A FITS header card given for a keyword the encoder writes itself
    /// (SIMPLE, BITPIX, NAXISn, BZERO, ...) or that is not a value card.
    #[error(
        "invalid input: FITS card {key}: the encoder writes this keyword itself or it is not a value card"
    )]
    FitsReservedKey {
        /// The keyword.
        key: String,
    },
    /// A FITS keyword given twice.
    #[error("invalid input: FITS card {key} is given twice")]
    FitsDuplicateKey {
        /// The keyword.
        key: String,
    },
    /// A FITS card that cannot be written: a bad keyword, a value or
    /// comment that is not printable ASCII or not finite, or a card longer
    /// than 80 characters; `reason` says which.
    #[error("invalid input: FITS card {key:?}: {reason}")]
    FitsCard {
        /// The keyword.
        key: String,
        /// What is wrong with the card.
        reason: String,
    },
    /// An output name whose extension names no format pgrf writes frames in.
    #[error("{path}: unknown frame format: name the output .dng, or .fits, .fit or .fts for FITS")]
    UnknownExtension {
        /// The output file.
        path: PathBuf,
    },
    /// An output file that could not be written atomically.
    #[error(transparent)]
    Write(#[from] pgrf_core::WriteError),
    /// An input folder that cannot be listed or holds no files.
    #[error("{path}: {reason}")]
    Folder {
        /// The folder.
        path: PathBuf,
        /// Why it gives no files.
        reason: String,
    },
}

impl RawError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        RawError::Io {
            path: path.to_path_buf(),
            error: source,
        }
    }

    pub(crate) fn decode(path: &Path, reason: impl Into<String>) -> Self {
        RawError::Decode {
            path: path.to_path_buf(),
            reason: one_line(reason.into()),
        }
    }

    pub(crate) fn fits_keyword(path: &Path, error: crate::fits::KeywordError) -> Self {
        RawError::FitsKeyword {
            path: path.to_path_buf(),
            error,
        }
    }

    pub(crate) fn folder(path: &Path, reason: impl Into<String>) -> Self {
        RawError::Folder {
            path: path.to_path_buf(),
            reason: reason.into(),
        }
    }

    pub(crate) fn unsupported(path: &Path, reason: impl Into<String>) -> Self {
        RawError::Unsupported {
            path: path.to_path_buf(),
            reason: one_line(reason.into()),
        }
    }
}

/// Decoder messages sometimes carry newlines or long backtraces; keep the
/// first line so the CLI's "one line per error" promise holds.
pub(crate) fn one_line(s: String) -> String {
    let first = s
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty())
        .unwrap_or("unknown error");
    if first.len() > 300 {
        let mut cut = 300;
        while !first.is_char_boundary(cut) {
            cut -= 1;
        }
        format!("{}…", &first[..cut])
    } else {
        first.to_string()
    }
}

/// Result of every fallible function of the RAW layer.
pub type Result<T> = std::result::Result<T, RawError>;
