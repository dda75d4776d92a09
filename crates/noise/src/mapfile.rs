//! Files of named per-pixel maps: safetensors (f32, packed `(4, H/2, W/2)`,
//! or a monochrome sensor's calibration as one plane `(1, H, W)` of its
//! pixels) plus one JSON metadata record. Used for calibration files and for the
//! virtual sensor's ground truth, so both load the same way and any tool that
//! reads safetensors (numpy, PyTorch) can inspect them.

use crate::error::{NoiseError, Result};
use ndarray::{Array3, ArrayView3};
use pgrf_core::record::{self, RecordError};
use std::collections::BTreeMap;
use std::path::Path;

fn err(path: &Path, reason: impl std::fmt::Display) -> NoiseError {
    NoiseError::MapsFile {
        path: path.to_path_buf(),
        reason: reason.to_string(),
    }
}

/// Write `maps` and `meta` (a JSON document) atomically to `path`.
pub fn write_maps(
    path: &Path,
    maps: &[(&str, ArrayView3<f32>)],
    meta: &serde_json::Value,
) -> Result<()> {
    let owned: Vec<(&str, Vec<usize>, Vec<f32>)> = maps
        .iter()
        .map(|(name, a)| (*name, a.shape().to_vec(), a.iter().copied().collect()))
        .collect();
    let bytes = record::encode(
        owned.iter().map(|(n, s, v)| (*n, &s[..], &v[..])),
        &meta.to_string(),
    )
    .map_err(|e| err(path, e))?;
    pgrf_core::write_atomic(path, &bytes)?;
    Ok(())
}

/// Read a maps file: its JSON record and every tensor, which must be f32 of
/// rank 3 with 4 planes (packed) or 1 (a sensor's pixels); which the
/// record allows is its reader's to check.
pub fn read_maps(path: &Path) -> Result<(serde_json::Value, BTreeMap<String, Array3<f32>>)> {
    let bytes = std::fs::read(path).map_err(|e| err(path, e))?;
    decode_maps(&bytes, path)
}

/// [`read_maps`] on bytes already in memory; `path` only names the source in
/// messages. Any bytes give a map set or one error, never a panic (fuzzed).
pub fn decode_maps(
    bytes: &[u8],
    path: &Path,
) -> Result<(serde_json::Value, BTreeMap<String, Array3<f32>>)> {
    let rec = record::decode(bytes).map_err(|e| match e {
        RecordError::NoRecord => err(path, "no pgrf metadata record (not a pgrf maps file)"),
        e => err(path, e),
    })?;
    let meta: serde_json::Value =
        serde_json::from_str(&rec.meta).map_err(|e| err(path, format!("bad metadata: {e}")))?;
    let mut maps = BTreeMap::new();
    for (name, t) in rec.tensors {
        let s = &t.shape;
        if s.len() != 3 || !(s[0] == 4 || s[0] == 1) {
            return Err(err(
                path,
                format!("tensor '{name}' has shape {s:?}, expected [4, H, W] or [1, H, W]"),
            ));
        }
        let a = Array3::from_shape_vec((s[0], s[1], s[2]), t.values).map_err(|e| err(path, e))?;
        maps.insert(name, a);
    }
    Ok((meta, maps))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_refusals() {
        let dir = std::env::temp_dir().join(format!("pgrf-mapfile-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let a = Array3::from_shape_fn((4, 3, 5), |(p, i, j)| (p * 100 + i * 10 + j) as f32 * 0.5);
        let b = Array3::from_elem((4, 3, 5), -1.25f32);
        let meta = serde_json::json!({"iso": 1600, "camera": "x"});
        let p = dir.join("m.safetensors");
        write_maps(&p, &[("a", a.view()), ("b", b.view())], &meta).unwrap();
        let (m, maps) = read_maps(&p).unwrap();
        assert_eq!(m, meta);
        assert_eq!(maps["a"], a);
        assert_eq!(maps["b"], b);
        std::fs::write(dir.join("junk.safetensors"), b"not a tensor file").unwrap();
        assert!(read_maps(&dir.join("junk.safetensors"))
            .unwrap_err()
            .to_string()
            .contains("safetensors"));
        assert!(read_maps(&dir.join("missing.safetensors")).is_err());
    }
}
