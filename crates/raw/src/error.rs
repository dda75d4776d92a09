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
    /// A readable file of a kind pgrf does not handle: linear (demosaiced) or
    /// monochrome data, X-Trans, floating-point samples.
    #[error("{path}: unsupported: {reason}")]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// What about it pgrf cannot handle, on one line.
        reason: String,
    },
    /// Arguments or in-memory data that cannot work: bad levels or geometry,
    /// a buffer of the wrong length, an encoder failure.
    #[error("invalid input: {0}")]
    Invalid(String),
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
