//! Files of named per-pixel maps: safetensors (f32, packed `(4, H/2, W/2)`)
//! plus one JSON metadata record. Used for calibration files and for the
//! virtual sensor's ground truth, so both load the same way and any tool that
//! reads safetensors (numpy, PyTorch) can inspect them.

use crate::error::{NoiseError, Result};
use ndarray::{Array3, ArrayView3};
use safetensors::tensor::{Dtype, SafeTensors, TensorView};
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// Metadata key holding pgrf's JSON record.
pub const META_KEY: &str = "pgrf";

fn err(path: &Path, reason: impl std::fmt::Display) -> NoiseError {
    NoiseError::Invalid(format!("{}: {reason}", path.display()))
}

/// Write `maps` and `meta` (a JSON document) atomically to `path`.
pub fn write_maps(
    path: &Path,
    maps: &[(&str, ArrayView3<f32>)],
    meta: &serde_json::Value,
) -> Result<()> {
    let owned: Vec<(String, Vec<u8>, Vec<usize>)> = maps
        .iter()
        .map(|(name, a)| {
            let bytes: Vec<u8> = a.iter().flat_map(|v| v.to_le_bytes()).collect();
            (name.to_string(), bytes, a.shape().to_vec())
        })
        .collect();
    let views: Vec<(String, TensorView)> = owned
        .iter()
        .map(|(n, b, s)| {
            Ok((
                n.clone(),
                TensorView::new(Dtype::F32, s.clone(), b).map_err(|e| err(path, e))?,
            ))
        })
        .collect::<Result<_>>()?;
    let mut info = HashMap::new();
    info.insert(META_KEY.to_string(), meta.to_string());
    let bytes = safetensors::tensor::serialize(views, Some(info)).map_err(|e| err(path, e))?;
    pgrf_raw::atomic::write_atomic(path, &bytes).map_err(|e| NoiseError::Invalid(e.to_string()))
}

/// Read a maps file: its JSON record and every tensor, which must be f32 of
/// rank 3 with 4 planes.
pub fn read_maps(path: &Path) -> Result<(serde_json::Value, BTreeMap<String, Array3<f32>>)> {
    let bytes = std::fs::read(path).map_err(|e| err(path, e))?;
    let st = SafeTensors::deserialize(&bytes)
        .map_err(|e| err(path, format!("not a safetensors file ({e})")))?;
    let (_, header) = SafeTensors::read_metadata(&bytes).map_err(|e| err(path, e))?;
    let meta_text = header
        .metadata()
        .as_ref()
        .and_then(|m| m.get(META_KEY))
        .ok_or_else(|| err(path, "no pgrf metadata record (not a pgrf maps file)"))?;
    let meta: serde_json::Value =
        serde_json::from_str(meta_text).map_err(|e| err(path, format!("bad metadata: {e}")))?;
    let mut maps = BTreeMap::new();
    for (name, view) in st.tensors() {
        if view.dtype() != Dtype::F32 {
            return Err(err(
                path,
                format!("tensor '{name}' is {:?}, expected F32", view.dtype()),
            ));
        }
        let s = view.shape();
        if s.len() != 3 || s[0] != 4 {
            return Err(err(
                path,
                format!("tensor '{name}' has shape {s:?}, expected [4, H, W]"),
            ));
        }
        let data: Vec<f32> = view
            .data()
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        let a = Array3::from_shape_vec((s[0], s[1], s[2]), data).map_err(|e| err(path, e))?;
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
