//! Calibration errors: one line each, naming the file when there is one.

#[derive(Debug, thiserror::Error)]
pub enum CalibError {
    #[error("{0}")]
    Raw(#[from] pgrf_raw::RawError),
    #[error("{0}")]
    Noise(#[from] pgrf_noise::NoiseError),
    #[error("{0}")]
    Invalid(String),
}

pub type Result<T> = std::result::Result<T, CalibError>;

pub(crate) fn invalid(msg: impl Into<String>) -> CalibError {
    CalibError::Invalid(msg.into())
}
