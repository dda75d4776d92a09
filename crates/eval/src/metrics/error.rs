//! The one error type of the metrics; every message is a single line that
//! says what was wrong with which input.

use thiserror::Error;

#[derive(Debug, Clone, PartialEq, Error)]
pub enum MetricError {
    /// The two images do not have the same `(C, H, W)` shape.
    #[error("output has shape {output:?} but reference has shape {reference:?}; metrics need equal shapes")]
    ShapeMismatch {
        output: Vec<usize>,
        reference: Vec<usize>,
    },
    /// An image has no pixels.
    #[error("{image} is empty (shape {shape:?})")]
    Empty {
        image: &'static str,
        shape: Vec<usize>,
    },
    /// A NaN or infinity in an input: refused rather than turned into a NaN score
    /// (or, after clamping, into a silently plausible one).
    #[error("{image} holds {value} at [{c}, {y}, {x}]; metrics need finite values")]
    NonFinite {
        image: &'static str,
        value: f32,
        c: usize,
        y: usize,
        x: usize,
    },
    /// A plane smaller than the SSIM window; scikit-image raises here too.
    #[error("image planes are {h}x{w}, smaller than the {win}x{win} SSIM window")]
    TooSmall { h: usize, w: usize, win: usize },
    /// An option outside its domain (even window, non-positive data range, ...).
    #[error("invalid metric option: {0}")]
    InvalidOption(String),
}
