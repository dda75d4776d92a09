//! One error type for the network crate: every failure reaches the user as
//! one line, so a message carries its own context (file, step, reason), and
//! the variants a caller may act on are told apart.

use std::path::PathBuf;

/// Why a network, weight file, configuration or run was refused.
#[derive(Debug, thiserror::Error)]
pub enum NnError {
    /// A weight or checkpoint file that cannot be used: unreadable, not a
    /// pgrf weight file, damaged, or from a newer pgrf.
    #[error("{}: {reason}", path.display())]
    BadFile {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// A weight file that holds the other method than the one asked for.
    #[error("{}: holds {found}, not {wanted}", path.display())]
    WrongMethod {
        /// The file.
        path: PathBuf,
        /// The method asked for.
        wanted: crate::Method,
        /// A description of what the file holds.
        found: String,
    },
    /// Tensors or arrays whose shapes do not fit each other (weights and
    /// architecture, a map and a frame, an input and a network).
    #[error("{0}")]
    SizeMismatch(String),
    /// A network or training configuration that cannot be built.
    #[error("{0}")]
    Config(String),
    /// Any other refused input, on one line.
    #[error("{0}")]
    Invalid(String),
    /// From reading or writing a RAW file.
    #[error(transparent)]
    Raw(#[from] pgrf_raw::RawError),
    /// From the noise model or a profile.
    #[error(transparent)]
    Noise(#[from] pgrf_noise::NoiseError),
    /// An output file could not be written.
    #[error(transparent)]
    Write(#[from] pgrf_core::WriteError),
}

/// The crate's result type.
pub type Result<T> = std::result::Result<T, NnError>;
