//! The small models pgrf ships, built into the library (and so into the
//! `pgrf` binary and the Python package) so `pgrf demo`, `--model
//! builtin:spc|builtin:pgrf` and `pgrf.Model.load("builtin:spc")` work on a
//! fresh machine with no files. MODELS.md records how each was trained.

use pgrf_nn::backend::DeviceKind;
use pgrf_nn::infer::restorer::load_bytes;
use pgrf_nn::infer::{Restore, SamplerChoice};
use pgrf_nn::NnError;
use std::path::Path;

/// SPC: residual SID U-Net, width 16.
pub const SPC: &[u8] = include_bytes!("../../../models/spc.safetensors");
/// PGRF: residual SR3 (16 channels x [1, 2, 2, 4]) correcting the SPC's
/// restoration (the SPC inside it), with its searched t2.
pub const PGRF: &[u8] = include_bytes!("../../../models/pgrf.safetensors");

/// The names `--model` accepts for the built-in weights.
pub const NAMES: [&str; 2] = ["builtin:spc", "builtin:pgrf"];

/// Why a model could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// A `builtin:` name that is not one of [`NAMES`].
    #[error("no such built-in model (there are {})", NAMES.join(", "))]
    NoSuchBuiltin {
        /// The name given.
        name: String,
    },
    /// The weight file could not be read or used.
    #[error(transparent)]
    Network(#[from] NnError),
}

/// The bytes of a built-in model named like `builtin:spc`.
pub fn lookup(name: &Path) -> Option<&'static [u8]> {
    match name.to_str()? {
        "builtin:spc" => Some(SPC),
        "builtin:pgrf" => Some(PGRF),
        _ => None,
    }
}

/// Load a model: a built-in name or a weight file, on `device`, sampled as
/// `choice` says.
pub fn load_model(
    path: &Path,
    choice: SamplerChoice,
    device: DeviceKind,
) -> Result<Box<dyn Restore>, ModelError> {
    if let Some(bytes) = lookup(path) {
        return Ok(load_bytes(path, bytes, choice, device)?);
    }
    match path.to_str() {
        Some(name) if name.starts_with("builtin:") => Err(ModelError::NoSuchBuiltin {
            name: name.to_string(),
        }),
        _ => Ok(pgrf_nn::infer::load(path, choice, device)?),
    }
}
