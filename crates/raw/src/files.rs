//! Input folders: which files of a folder a command reads.

use crate::error::{RawError, Result};
use std::path::{Path, PathBuf};

/// RAW files in `dir`, sorted by name (hidden files skipped).
pub fn list_files(dir: &Path) -> Result<Vec<PathBuf>> {
    if !dir.is_dir() {
        return Err(RawError::folder(dir, "not a folder"));
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| RawError::folder(dir, e.to_string()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.is_file()
                && !p
                    .file_name()
                    .map(|n| n.to_string_lossy().starts_with('.'))
                    .unwrap_or(true)
        })
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(RawError::folder(dir, "folder has no files"));
    }
    Ok(files)
}
