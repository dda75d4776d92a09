//! Training checkpoints: everything needed to continue a run exactly where it
//! stopped — network and Adam moments (burn records, full precision), the
//! step, the configuration it was started with and the elapsed time. The data
//! stream needs no state: batches are a function of (seed, index).
//!
//! Layout: magic "PGRFCKPT", u32 version, then length-prefixed (u64 LE)
//! blocks: JSON state, network record, optimiser record and (version 2) the
//! moving average of the weights ([`crate::ema`], safetensors; empty when the
//! run keeps none). Version 1 files (three blocks) still load. Written
//! atomically, so a run killed mid-write keeps its previous checkpoint.

use crate::error::{NnError, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

const MAGIC: &[u8; 8] = b"PGRFCKPT";
const VERSION: u32 = 2;

/// The JSON part of a checkpoint.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub(crate) struct CheckpointState {
    /// The method being trained.
    pub(crate) task: crate::Method,
    /// The architecture record (same JSON as in weight files).
    pub(crate) arch: serde_json::Value,
    /// Steps completed.
    pub(crate) step: u64,
    /// Total steps the run was configured for.
    pub(crate) steps: u64,
    /// The run's seed (a resume must use the same).
    pub(crate) seed: u64,
    /// Crops per step (a resume must use the same).
    pub(crate) batch: usize,
    /// Side of the packed training crops (a resume must use the same).
    pub(crate) patch: usize,
    /// Training seconds so far (excluding time between runs).
    pub(crate) elapsed_s: f64,
    /// Loss of the last step before the checkpoint.
    pub(crate) last_loss: Option<f32>,
    /// Latest validation PSNR in dB, if validated.
    pub(crate) last_val_psnr: Option<f32>,
}

/// A checkpoint read back: state plus the two burn records as bytes.
pub(crate) struct Checkpoint {
    /// The JSON part.
    pub(crate) state: CheckpointState,
    /// The network's burn record (full precision).
    pub(crate) model: Vec<u8>,
    /// The optimiser's burn record (Adam moments).
    pub(crate) optim: Vec<u8>,
    /// The moving average of the weights, if the run kept one.
    pub(crate) ema: Option<Vec<u8>>,
}

fn err(path: &Path, reason: impl std::fmt::Display) -> NnError {
    NnError::BadFile {
        path: path.to_path_buf(),
        reason: reason.to_string(),
    }
}

/// The checkpoint file's bytes (layout in the module documentation).
fn encode(state: &CheckpointState, model: &[u8], optim: &[u8], ema: &[u8]) -> Result<Vec<u8>> {
    let json = serde_json::to_vec(state).map_err(|e| NnError::Invalid(e.to_string()))?;
    let mut out = Vec::with_capacity(12 + 32 + json.len() + model.len() + optim.len() + ema.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&VERSION.to_le_bytes());
    for block in [&json[..], model, optim, ema] {
        out.extend_from_slice(&(block.len() as u64).to_le_bytes());
        out.extend_from_slice(block);
    }
    Ok(out)
}

/// Write a checkpoint atomically; `ema` is the moving average's block
/// (empty without one).
pub(crate) fn save(
    path: &Path,
    state: &CheckpointState,
    model: &[u8],
    optim: &[u8],
    ema: &[u8],
) -> Result<()> {
    let bytes = encode(state, model, optim, ema)?;
    Ok(pgrf_core::write_atomic(path, &bytes)?)
}

/// Parse checkpoint bytes; `path` names them in errors. Any truncation,
/// trailing bytes or another version is refused.
fn decode(path: &Path, bytes: &[u8]) -> Result<Checkpoint> {
    if bytes.len() < 12 || &bytes[..8] != MAGIC {
        return Err(err(path, "not a pgrf training checkpoint"));
    }
    let version = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
    let names: &[&str] = match version {
        1 => &["state", "network", "optimiser"],
        VERSION => &["state", "network", "optimiser", "moving average"],
        _ => {
            return Err(err(
                path,
                format!("checkpoint version {version}, this pgrf reads 1 and {VERSION}"),
            ))
        }
    };
    let mut at = 12usize;
    let mut blocks = Vec::with_capacity(names.len());
    for &name in names {
        let len = bytes
            .get(at..at + 8)
            .map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")) as usize)
            .ok_or_else(|| err(path, format!("truncated before the {name} block")))?;
        at += 8;
        let end = at
            .checked_add(len)
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| err(path, format!("truncated in the {name} block")))?;
        blocks.push(bytes[at..end].to_vec());
        at = end;
    }
    if at != bytes.len() {
        return Err(err(
            path,
            format!("trailing bytes after the {} block", names[names.len() - 1]),
        ));
    }
    let ema = if version >= 2 {
        Some(blocks.pop().expect("four blocks")).filter(|b| !b.is_empty())
    } else {
        None
    };
    let optim = blocks.pop().expect("three blocks");
    let model = blocks.pop().expect("three blocks");
    let state: CheckpointState = serde_json::from_slice(&blocks[0])
        .map_err(|e| err(path, format!("bad state record: {e}")))?;
    Ok(Checkpoint {
        state,
        model,
        optim,
        ema,
    })
}

/// Read and parse the checkpoint at `path`.
pub(crate) fn load(path: &Path) -> Result<Checkpoint> {
    let bytes = std::fs::read(path).map_err(|e| err(path, e))?;
    decode(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state() -> CheckpointState {
        CheckpointState {
            task: crate::Method::Pgrf,
            arch: serde_json::json!({"arch": "sr3"}),
            step: 40,
            steps: 100,
            seed: 7,
            batch: 2,
            patch: 64,
            elapsed_s: 12.5,
            last_loss: Some(0.1),
            last_val_psnr: None,
        }
    }

    #[test]
    fn round_trip_and_every_truncation_is_refused() {
        let p = Path::new("ck.bin");
        for ema in [&[][..], &[6u8, 7, 8, 9][..]] {
            let bytes = encode(&state(), &[1, 2, 3], &[4, 5], ema).unwrap();
            let c = decode(p, &bytes).unwrap();
            assert_eq!(c.state, state());
            assert_eq!(
                (c.model.as_slice(), c.optim.as_slice()),
                (&[1u8, 2, 3][..], &[4u8, 5][..])
            );
            assert_eq!(c.ema.as_deref(), (!ema.is_empty()).then_some(ema));
            for cut in 0..bytes.len() {
                assert!(decode(p, &bytes[..cut]).is_err(), "cut at {cut}");
            }
            let mut extra = bytes.clone();
            extra.push(0);
            assert!(decode(p, &extra).is_err());
        }
    }

    /// A version 1 checkpoint (three blocks, before moving averages) still
    /// loads, with no average; an unknown version is refused.
    #[test]
    fn version_one_checkpoints_still_load() {
        let p = Path::new("ck.bin");
        let v2 = encode(&state(), &[1, 2, 3], &[4, 5], &[]).unwrap();
        // The same file as version 1 wrote it: version 1, no fourth block.
        let mut v1 = v2[..v2.len() - 8].to_vec();
        v1[8..12].copy_from_slice(&1u32.to_le_bytes());
        let c = decode(p, &v1).unwrap();
        assert_eq!(
            (c.state, c.model, c.optim, c.ema),
            (state(), vec![1, 2, 3], vec![4, 5], None)
        );
        let mut v3 = v2.clone();
        v3[8..12].copy_from_slice(&3u32.to_le_bytes());
        let e = decode(p, &v3).err().unwrap().to_string();
        assert!(e.contains("version 3"), "{e}");
    }
}
