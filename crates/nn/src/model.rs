//! A network and its weight file: build the network a file's record
//! describes and load its tensors into it, or write a network's parameters
//! with a record. The file format itself is [`crate::weights`]'s; the
//! networks are [`crate::arch`]'s.

use crate::arch::{Net, Sr3Unet};
use crate::error::{NnError, Result};
use crate::named::NamedTensor;
use crate::weights::{self, WeightMeta};
use burn::tensor::backend::Backend;
use std::collections::BTreeMap;
use std::path::Path;

impl<B: Backend> Net<B> {
    /// Write the parameters and `meta` as a weight file at `path`, atomically
    /// ([`crate::weights`]).
    pub fn save(&self, path: &Path, meta: &WeightMeta) -> Result<()> {
        let bytes = weights::encode(&self.parameters(), meta)?;
        Ok(pgrf_core::write_atomic(path, &bytes)?)
    }
}

/// Build the network the file describes and load its weights on `device`;
/// every tensor must fit the recorded architecture by name and shape.
pub fn load<B: Backend>(path: &Path, device: &B::Device) -> Result<(Net<B>, WeightMeta)> {
    load_bytes(path, &weights::read_bytes(path)?, device)
}

/// [`load`] from a weight file's bytes (weights built into the binary);
/// `path` names them in errors.
pub(crate) fn load_bytes<B: Backend>(
    path: &Path,
    bytes: &[u8],
    device: &B::Device,
) -> Result<(Net<B>, WeightMeta)> {
    let (meta, tensors) = weights::from_bytes(bytes, path)?;
    let net = fit::<B>(path, &meta, &tensors, device)?;
    Ok((net, meta))
}

/// The network `meta` records, holding `tensors` (read from `path`): every
/// tensor must fit it by name and shape. A record claiming more parameters
/// than the file holds values is refused before the network is built, so
/// what is allocated is bounded by the file itself.
fn fit<B: Backend>(
    path: &Path,
    meta: &WeightMeta,
    tensors: &BTreeMap<String, NamedTensor>,
    device: &B::Device,
) -> Result<Net<B>> {
    let held: u64 = tensors.values().map(|t| t.values.len() as u64).sum();
    let needed = meta.arch.min_params();
    if needed > held as f64 {
        return Err(NnError::SizeMismatch(format!(
            "{}: weights do not fit {}: it has at least {needed:.0} parameters, the file holds {held} values",
            path.display(),
            meta.arch.describe()
        )));
    }
    let fit = |e: crate::named::Mismatch| {
        NnError::SizeMismatch(format!(
            "{}: weights do not fit {}: {e}",
            path.display(),
            meta.arch.describe()
        ))
    };
    meta.arch
        .init::<B>(device)
        .map_err(|e| NnError::Config(format!("{}: {e}", path.display())))?
        .assign(tensors, device)
        .map_err(fit)
}

/// Check that a weight file's tensors are the network its record describes
/// (names, shapes, nothing left over), as [`load`] would, without keeping
/// the network: what commands that pass the tensors on (`export-weights`)
/// check first.
pub(crate) fn check_fit(
    path: &Path,
    meta: &WeightMeta,
    tensors: &BTreeMap<String, NamedTensor>,
) -> Result<()> {
    fit::<crate::backend::Cpu>(path, meta, tensors, &Default::default()).map(|_| ())
}

/// The weights of `path` as a network of `arch`, to start a run from
/// (`--init`): the file's own network when it is `arch`, else adapted to it
/// ([`crate::arch::Architecture::adapt_start`]: its unconditioned form
/// widened to take the noise planes, or a narrower SID U-Net written into
/// the old channels of `fresh`, the run's seeded network). Says how.
pub(crate) fn load_init<B: Backend>(
    path: &Path,
    arch: &crate::arch::Architecture,
    fresh: Net<B>,
    device: &B::Device,
) -> Result<(Net<B>, WeightMeta, crate::arch::StartAdapted)> {
    let (meta, mut tensors) = weights::read(path)?;
    weights::check_arch(path, &meta, arch)?;
    let fit = |e: crate::named::Mismatch| {
        NnError::SizeMismatch(format!(
            "{}: weights do not fit {}: {e}",
            path.display(),
            arch.describe()
        ))
    };
    // `arch` is the run's own (already checked against memory), so the
    // file's tensors are assigned to it however they were adapted.
    let adapted = arch
        .adapt_start(&meta.arch, &mut tensors, &fresh)
        .map_err(fit)?;
    let net = fresh.assign(&tensors, device).map_err(fit)?;
    Ok((net, meta, adapted))
}

/// Load a file that must hold the SPC denoiser.
#[cfg(test)]
pub(crate) fn load_denoiser<B: Backend>(
    path: &Path,
    device: &B::Device,
) -> Result<(crate::arch::SidUnet<B>, WeightMeta)> {
    let (net, m) = load::<B>(path, device)?;
    match net.into_denoiser() {
        Some(n) => Ok((n, m)),
        None => Err(NnError::WrongMethod {
            path: path.to_path_buf(),
            wanted: crate::Method::Spc,
            found: format!("a {}", m.arch.describe()),
        }),
    }
}

/// Load a file that must hold the PGRF flow model.
pub fn load_flow<B: Backend>(path: &Path, device: &B::Device) -> Result<(Sr3Unet<B>, WeightMeta)> {
    let (net, m) = load::<B>(path, device)?;
    match net.into_flow() {
        Some(n) => Ok((n, m)),
        None => Err(NnError::WrongMethod {
            path: path.to_path_buf(),
            wanted: crate::Method::Pgrf,
            found: format!("an {}", m.arch.describe()),
        }),
    }
}
