//! Errors of the noise crate, one line each.

#[derive(Debug, thiserror::Error)]
pub enum NoiseError {
    #[error("profile {name}: {reason}")]
    Profile { name: String, reason: String },
    #[error("invalid noise setting: {0}")]
    Invalid(String),
    /// An output file could not be written.
    #[error(transparent)]
    Write(#[from] pgrf_core::WriteError),
}

pub type Result<T> = std::result::Result<T, NoiseError>;
