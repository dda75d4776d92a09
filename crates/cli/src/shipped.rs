//! The small models pgrf ships, built into the binary so `pgrf demo` (and
//! `--model builtin:spc|builtin:pgrf`) work on a fresh machine with no files.
//! MODELS.md records how each was trained.

use pgrf_nn::backend::DeviceKind;
use pgrf_nn::infer::restorer::load_bytes;
use pgrf_nn::infer::{Restore, SamplerChoice};
use std::path::Path;

/// SPC: residual SID U-Net, width 16.
pub const SPC: &[u8] = include_bytes!("../../../models/spc.safetensors");
/// PGRF: residual SR3 (16 channels x [1, 2, 2, 4]) with its searched t2.
pub const PGRF: &[u8] = include_bytes!("../../../models/pgrf.safetensors");

/// The names `--model` accepts for the built-in weights.
pub const NAMES: [&str; 2] = ["builtin:spc", "builtin:pgrf"];

/// The bytes of a built-in model named like `builtin:spc`.
pub fn lookup(name: &Path) -> Option<&'static [u8]> {
    match name.to_str()? {
        "builtin:spc" => Some(SPC),
        "builtin:pgrf" => Some(PGRF),
        _ => None,
    }
}

/// Load `--model`: a built-in name or a weight file.
pub fn load_model(
    path: &Path,
    choice: SamplerChoice,
    device: DeviceKind,
) -> anyhow::Result<Box<dyn Restore>> {
    if let Some(bytes) = lookup(path) {
        return Ok(load_bytes(path, bytes, choice, device)?);
    }
    if path.to_str().is_some_and(|s| s.starts_with("builtin:")) {
        anyhow::bail!("no such built-in model (there are {})", NAMES.join(", "));
    }
    Ok(pgrf_nn::infer::load(path, choice, device)?)
}
