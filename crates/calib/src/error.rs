//! Calibration errors: one line each, naming the file when there is one.

/// Why a calibration could not be made, read, written or applied.
#[derive(Debug, thiserror::Error)]
pub enum CalibError {
    /// A frame could not be decoded or packed.
    #[error("{0}")]
    Raw(#[from] pgrf_raw::RawError),
    /// The maps file could not be read or written, or the maps are invalid
    /// for the noise model.
    #[error("{0}")]
    Noise(#[from] pgrf_noise::NoiseError),
    /// Inputs that do not make a calibration (mismatched frames, too few
    /// frames or exposures, another camera or ISO, a malformed record).
    #[error("{0}")]
    Invalid(String),
}

/// Result of every fallible function of the calibration crate.
pub type Result<T> = std::result::Result<T, CalibError>;

pub(crate) fn invalid(msg: impl Into<String>) -> CalibError {
    CalibError::Invalid(msg.into())
}
