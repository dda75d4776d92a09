//! Errors of the noise crate, one line each.

/// Why a profile, a noise setting or an output was refused.
#[derive(Debug, thiserror::Error)]
pub enum NoiseError {
    /// A camera profile that is unknown, unreadable or fails validation
    /// (missing keys, negative standard deviations, unsorted ISO table).
    #[error("profile {name}: {reason}")]
    Profile {
        /// The profile's name or file.
        name: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A parameter, map or image that the models cannot use (non-positive
    /// ratio, shape mismatch, invalid map value, ...).
    #[error("invalid noise setting: {0}")]
    Invalid(String),
    /// An output file could not be written.
    #[error(transparent)]
    Write(#[from] pgrf_core::WriteError),
}

/// Result of every fallible function of the noise crate.
pub type Result<T> = std::result::Result<T, NoiseError>;
