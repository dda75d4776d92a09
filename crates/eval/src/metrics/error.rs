//! The one error type of the metrics; every message is a single line that
//! says what was wrong with which input.

use thiserror::Error;

/// Why two images could not be measured.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum MetricError {
    /// The two images do not have the same `(C, H, W)` shape.
    #[error("output has shape {output:?} but reference has shape {reference:?}; metrics need equal shapes")]
    ShapeMismatch {
        /// Shape of the output.
        output: Vec<usize>,
        /// Shape of the reference.
        reference: Vec<usize>,
    },
    /// An image has no pixels.
    #[error("{image} is empty (shape {shape:?})")]
    Empty {
        /// Which image ("output" or "reference").
        image: &'static str,
        /// Its shape.
        shape: Vec<usize>,
    },
    /// A NaN or infinity in an input: refused rather than turned into a NaN score
    /// (or, after clamping, into a silently plausible one).
    #[error("{image} holds {value} at [{c}, {y}, {x}]; metrics need finite values")]
    NonFinite {
        /// Which image ("output" or "reference").
        image: &'static str,
        /// The offending value.
        value: f32,
        /// Its channel.
        c: usize,
        /// Its row.
        y: usize,
        /// Its column.
        x: usize,
    },
    /// A plane smaller than the SSIM window; scikit-image raises here too.
    #[error("image planes are {h}x{w}, smaller than the {win}x{win} SSIM window")]
    TooSmall {
        /// Plane height in pixels.
        h: usize,
        /// Plane width in pixels.
        w: usize,
        /// Side of the SSIM window.
        win: usize,
    },
    /// An option outside its domain (even window, non-positive data range, ...).
    #[error("invalid metric option: {0}")]
    InvalidOption(String),
}
