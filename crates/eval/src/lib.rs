//! Evaluation for pgrf: image-quality metrics computed exactly as the
//! low-light RAW literature computes them (scikit-image's PSNR and SSIM under
//! the ELD protocol), so that numbers pgrf prints can sit in the same table as
//! published ones. Dataset protocols (ELD, SID, paired lists) and comparison
//! tables build on these; [`run_protocol`] runs a whole
//! protocol from an [`EvalConfig`] over [`MethodUnderTest`]s (pgrf-nn's
//! models implement it), and [`compare_files`] measures one file against
//! another.
//!
//! No deep-learning framework here: plain `ndarray` arrays and rayon, like the
//! physics crates, so the metrics can judge any producer's output.

#![warn(missing_docs)]

mod compare;
pub mod dataset;
pub mod evaluation;
#[cfg(feature = "clap")]
pub mod flags;
pub mod method;
mod metrics;
pub mod npy;

pub use compare::{compare_files, CompareError, FileScores};
pub use evaluation::{run_protocol, worst_path, EvalConfig, EvalError, Evaluation, SyntheticSpec};
pub use method::{CaseInfo, CaseNoise, MethodUnderTest, RestoreError};

pub use metrics::cast;
pub use metrics::{artefacts, seams, speckles, Seams, Speckles};
pub use metrics::{
    colour_cast, evaluate, illuminance_correct, illuminance_gain, psnr, ssim, CameraColour, Cast,
    IlluminanceGain, MetricError, Protocol, Scores, SsimOptions,
};
