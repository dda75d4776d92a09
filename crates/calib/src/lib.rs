//! Per-pixel sensor calibration from bias, dark and flat-field stacks:
//! streaming statistics, estimators, calibration files and report plots.
//!
//! Physics-side crate: ndarray and rayon, no deep-learning framework.

#![warn(missing_docs)]

mod bank;
pub mod calibrate;
mod calibration;
mod columns;
mod error;
pub mod estimate;
#[cfg(feature = "clap")]
pub mod flags;
pub mod light;
pub mod masters;
mod messages;
pub mod mix;
pub mod outputs;
mod ppcc;
pub mod reduce;
mod sample_sd;
pub mod stack;
mod stats;
pub mod synth;
pub mod temperature;

pub use calibrate::{calibrate, CalibrateInput, CalibrationRun};
pub use calibration::{CalibMaps, CalibMeta, Calibration};
pub use error::{CalibError, FrameField, RecordFault, Result};
pub use estimate::GainMethod;
pub use outputs::{
    calibrate_to_files, CalibrateConfig, CalibrateOutcome, DarktableOutcome, DarktableOutput,
    ReportOutput, RunHooks,
};
