//! Shared helpers for tests that read the read-only material in ../shared/data.
#![allow(dead_code)]

use std::path::PathBuf;

/// `../shared/data` next to the repository root. Tests that call this are
/// marked `#[cfg_attr(not(shared_data), ignore = ...)]`, so they only run
/// where the folder is.
pub fn data_dir() -> PathBuf {
    pgrf_core::shared_data_dir().expect("../shared/data (the test should be ignored without it)")
}

/// A fresh scratch folder for one test.
pub fn scratch(name: &str) -> PathBuf {
    let d = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("pgrf-raw-test-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}
