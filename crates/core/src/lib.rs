//! Framework-free basics that every pgrf crate shares, so that each exists
//! once: atomic file writes and the checks on output paths, the robust statistics helper, seeding of
//! thread-count-independent random streams, the progress interface the
//! libraries report through, the safetensors + JSON record format used by
//! calibration files and weight files, the process's memory figures, and the
//! one error every value parser returns ([`parse::ParseError`]).
//!
//! It depends on no other pgrf crate and on no deep-learning framework.

#![warn(missing_docs)]

mod atomic;
pub mod disk;
pub mod exit;
pub mod mem;
pub mod number;
pub mod panic_guard;
pub mod parse;
pub mod paths;
mod progress;
pub mod record;
pub mod seed;
pub mod stats;
pub mod weighted;

pub use atomic::{write_atomic, WriteError};
pub use progress::{NoProgress, Progress};

/// `../shared/data` beside the repository (real captures and published
/// tables the tests compare against), or None where it is absent. Tests that
/// need it are marked `#[cfg_attr(not(shared_data), ignore = ...)]` through
/// the build script `crates/core/shared_data_cfg.rs`, so they report as
/// ignored rather than passed without it.
pub fn shared_data_dir() -> Option<std::path::PathBuf> {
    let d = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    d.is_dir().then_some(d)
}
