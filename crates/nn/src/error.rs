//! One error type for the network crate: every failure reaches the user as
//! one line, so a message carries its own context (file, step, reason).

#[derive(Debug, thiserror::Error)]
pub enum NnError {
    #[error("{0}")]
    Invalid(String),
    #[error(transparent)]
    Raw(#[from] pgrf_raw::RawError),
    #[error(transparent)]
    Noise(#[from] pgrf_noise::NoiseError),
    /// An output file could not be written.
    #[error(transparent)]
    Write(#[from] pgrf_core::WriteError),
}

pub type Result<T> = std::result::Result<T, NnError>;
