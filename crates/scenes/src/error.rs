//! One error type for everything the training material can refuse.
//!
//! The RAW layer's own refusals (levels, geometry of a frame) pass through
//! unchanged; the rest are typed variants naming what was wrong. Every
//! message is one line, worded as it was when this code lived in pgrf-raw
//! (`invalid input: ...`, `PATH: cannot decode: ...`), because the CLI
//! prints it verbatim and scripts and tests match on it.

use pgrf_raw::RawError;
use std::path::PathBuf;

/// Why a scene, chart, photo or unprocessing could not be made.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// A frame the RAW layer refused (its levels, size or samples).
    #[error(transparent)]
    Raw(#[from] RawError),
    /// A bit depth too small for the white level, or above 16.
    #[error("invalid input: {bits} bits cannot hold white level {white} (needs {needed}..=16)")]
    BitsForWhite {
        /// The bit depth asked for.
        bits: u32,
        /// The white level in DN.
        white: u32,
        /// The smallest bit depth that holds `white`.
        needed: u32,
    },
    /// A demo scene smaller than 64 pixels a side, or of odd size.
    #[error(
        "invalid input: demo scene size {width}x{height}: width and height must be even and at least 64"
    )]
    DemoSize {
        /// Width asked for, pixels.
        width: usize,
        /// Height asked for, pixels.
        height: usize,
    },
    /// A photo file that cannot be read as an RGB photo (unreadable,
    /// truncated, not an image, CMYK, grey-scale).
    #[error("{path}: cannot decode: {reason}")]
    Photo {
        /// The file.
        path: PathBuf,
        /// What was wrong with it, on one line.
        reason: String,
    },
    /// A downscale factor of 0, or one that leaves no pixel.
    #[error("invalid input: cannot downscale a {width}x{height} photo by {factor}")]
    Downscale {
        /// The photo's width, pixels.
        width: usize,
        /// The photo's height, pixels.
        height: usize,
        /// The factor asked for.
        factor: usize,
    },
    /// A camera file without what unprocessing needs; `missing` names it
    /// ("colour matrix", "as-shot white balance").
    #[error("invalid input: the camera file has no {missing}: cannot unprocess into its space")]
    NoCameraSpace {
        /// What the file lacks.
        missing: &'static str,
    },
    /// A colour matrix whose camera -> sRGB inverse does not exist.
    #[error("invalid input: unprocess: the colour matrix cannot be used (a row sums to zero)")]
    UnusableMatrix,
    /// An unprocessing exposure that is not a positive number.
    #[error("invalid input: unprocess: exposure must be a positive number, got {exposure}")]
    BadExposure {
        /// The exposure factor given.
        exposure: f32,
    },
    /// White-balance multipliers that are not all positive numbers.
    #[error("invalid input: unprocess: white-balance multipliers must be positive, got {wb:?}")]
    BadWhiteBalance {
        /// The multipliers R, G, B given.
        wb: [f32; 3],
    },
    /// A camera-from-sRGB matrix with a NaN or infinite entry.
    #[error("invalid input: unprocess: the colour matrix has a non-finite entry")]
    NonFiniteMatrix,
    /// An RGB buffer whose length is not `3 * width * height`, or a photo
    /// smaller than 2x2.
    #[error("invalid input: unprocess: {values} values for a {width}x{height} RGB image")]
    PhotoSize {
        /// Values in the buffer.
        values: usize,
        /// The photo's width, pixels.
        width: usize,
        /// The photo's height, pixels.
        height: usize,
    },
    /// A crop window that is empty or reaches past the photo.
    #[error(
        "invalid input: unprocess: a {cols}x{rows} window at ({y}, {x}) does not fit a {width}x{height} photo"
    )]
    WindowOutside {
        /// Top row of the window.
        y: usize,
        /// Left column of the window.
        x: usize,
        /// Width of the window, photo pixels (an even count, at least 2).
        cols: usize,
        /// Height of the window, photo pixels (an even count, at least 2).
        rows: usize,
        /// The photo's width, pixels.
        width: usize,
        /// The photo's height, pixels.
        height: usize,
    },
}

/// Result of every fallible function of the training material.
pub type Result<T> = std::result::Result<T, SceneError>;
