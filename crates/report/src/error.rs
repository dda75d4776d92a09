//! The one error type of the report crate.

use std::path::PathBuf;

/// Why a report could not be written. Every message is a single line because
/// the CLI prints errors verbatim, one per line.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Creating the folder is the caller's decision (it usually also holds
    /// the calibration file), so a missing one is refused, not created.
    #[error("report folder '{0}' does not exist")]
    MissingDir(PathBuf),
    /// The report path exists but is a file.
    #[error("report path '{0}' is not a folder")]
    NotADir(PathBuf),
    /// Data the report cannot show (wrong plane count, mismatched lengths).
    #[error("invalid report input: {0}")]
    Invalid(String),
    /// Nothing a picture could show: no panels, or no finite value to plot
    /// (a diverged model's PSNR); the sentence says which.
    #[error("{0}")]
    Empty(&'static str),
    /// The embedded font did not load.
    #[error("cannot load the embedded plot font: DejaVu Sans {face} is not a valid font")]
    Font {
        /// The face that failed ("regular" or "bold").
        face: &'static str,
    },
    /// plotters failed while drawing `file`.
    #[error("{file}: cannot draw: {reason}")]
    Plot {
        /// The picture being drawn.
        file: String,
        /// plotters' message, on one line.
        reason: String,
    },
    /// The pixels could not be encoded as PNG.
    #[error("{file}: cannot encode PNG: {reason}")]
    Encode {
        /// The picture being encoded.
        file: String,
        /// The encoder's message, on one line.
        reason: String,
    },
    /// The PNG or summary could not be written.
    #[error(transparent)]
    Write(#[from] pgrf_core::WriteError),
}
