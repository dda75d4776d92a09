//! Reading the tensors of a PyTorch checkpoint (`.pth`/`.pt`) or a
//! safetensors file, whatever dict they are nested in.
//!
//! `.pth` files go through burn's own reader (`burn-store`, the PyTorch
//! store of burn 0.21, the framework pgrf already runs on: it parses the
//! pickle into data and never executes it). Before it sees the file, pgrf
//! checks what the pickle asks for ([`super::pickle_check`]) and bounds the
//! zip's declared sizes, so a hostile file is refused in one line instead of
//! reaching a general-purpose reader.

use super::pickle_check;
use crate::error::{NnError, Result};
use crate::named::NamedTensor;
use std::collections::BTreeMap;
use std::io::Read;
use std::path::Path;

/// Most uncompressed bytes a checkpoint's zip entries may declare in all:
/// the full-width SID U-Net is 31 MB of f32; this leaves room for f64
/// copies and optimiser states without letting a zip bomb allocate.
const MAX_UNPACKED: u64 = 1 << 30;

/// The tensors of a checkpoint, by their names in the file (a nesting such
/// as `state_dict.` or `netG.` still on them).
pub struct TorchTensors {
    /// Every floating-point tensor of the file, as f32.
    pub tensors: BTreeMap<String, NamedTensor>,
    /// The container, in words ("PyTorch zip checkpoint", ...).
    pub format: &'static str,
    /// SHA-256 of the file's bytes, hex (the provenance an import records).
    pub sha256: String,
}

fn bad(path: &Path, reason: impl std::fmt::Display) -> NnError {
    NnError::BadFile {
        path: path.to_path_buf(),
        reason: reason.to_string(),
    }
}

/// Read every tensor of `path`: safetensors, a PyTorch zip checkpoint
/// (torch.save since 1.6), or a legacy pickle checkpoint.
pub fn read(path: &Path) -> Result<TorchTensors> {
    let bytes = std::fs::read(path).map_err(|e| bad(path, e))?;
    if bytes.is_empty() {
        return Err(bad(path, "file is empty"));
    }
    if bytes.starts_with(b"PK\x03\x04") {
        check_zip(path, &bytes)?;
        return Ok(TorchTensors {
            tensors: burn_read(path)?,
            format: "PyTorch zip checkpoint",
            sha256: sha256(&bytes),
        });
    }
    if bytes.len() >= 8 {
        let n = u64::from_le_bytes(bytes[..8].try_into().expect("8 bytes"));
        if n > 1 && n < bytes.len() as u64 && bytes.get(8) == Some(&b'{') {
            return Ok(TorchTensors {
                tensors: read_safetensors(path, &bytes)?,
                format: "safetensors",
                sha256: sha256(&bytes),
            });
        }
    }
    if bytes.first() == Some(&0x80) {
        // A legacy checkpoint (torch < 1.6) starts with the magic-number
        // pickle, a LONG1 of 10 bytes; its first four pickles are magic,
        // protocol, system information and the data.
        let programs = if bytes.get(1..4) == Some(&[0x02, 0x8a, 0x0a]) {
            4
        } else {
            1
        };
        pickle_check::check(&bytes, programs).map_err(|e| bad(path, e))?;
        return Ok(TorchTensors {
            tensors: burn_read(path)?,
            format: "legacy PyTorch pickle checkpoint",
            sha256: sha256(&bytes),
        });
    }
    Err(bad(
        path,
        "neither a PyTorch checkpoint (zip or pickle) nor a safetensors file",
    ))
}

/// The zip's entries: sizes bounded, data.pkl's pickle checked.
fn check_zip(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes))
        .map_err(|e| bad(path, format!("not a readable zip archive ({e})")))?;
    let mut total = 0u64;
    let mut pkl = None;
    for i in 0..zip.len() {
        let f = zip
            .by_index_raw(i)
            .map_err(|e| bad(path, format!("zip entry {i}: {e}")))?;
        total = total.saturating_add(f.size());
        if f.name().ends_with("data.pkl") && pkl.is_none() {
            pkl = Some((i, f.size()));
        }
    }
    if total > MAX_UNPACKED {
        return Err(bad(
            path,
            format!(
                "the zip's entries unpack to {total} bytes, more than the {MAX_UNPACKED} a checkpoint of this network needs"
            ),
        ));
    }
    let (i, size) =
        pkl.ok_or_else(|| bad(path, "no data.pkl in the zip (not a torch.save file)"))?;
    let mut data = Vec::with_capacity(size as usize);
    zip.by_index(i)
        .map_err(|e| bad(path, format!("data.pkl: {e}")))?
        .take(size)
        .read_to_end(&mut data)
        .map_err(|e| bad(path, format!("data.pkl: {e}")))?;
    pickle_check::check(&data, 1)
        .map(|_| ())
        .map_err(|e| bad(path, format!("data.pkl: {e}")))
}

/// Every floating-point tensor through burn-store's reader, as f32.
fn burn_read(path: &Path) -> Result<BTreeMap<String, NamedTensor>> {
    let reader = pgrf_core::panic_guard::quietly(
        "the PyTorch reader failed on this file (malformed or truncated?)",
        || burn_store::pytorch::PytorchReader::new(path),
    )
    .map_err(|e| bad(path, e))?
    .map_err(|e| bad(path, one_line(&e.to_string())))?;
    let mut out = BTreeMap::new();
    for (name, snap) in reader.into_tensors() {
        let shape = snap.shape.to_vec();
        let data = snap
            .to_data()
            .map_err(|e| bad(path, format!("tensor {name}: {e:?}")))?;
        if !data.dtype.is_float() {
            continue;
        }
        let values = data
            .convert::<f32>()
            .to_vec::<f32>()
            .map_err(|e| bad(path, format!("tensor {name}: {e:?}")))?;
        if values.len() != shape.iter().product::<usize>() {
            return Err(bad(
                path,
                format!("tensor {name}: {} values for shape {shape:?}", values.len()),
            ));
        }
        out.insert(name, NamedTensor { shape, values });
    }
    Ok(out)
}

/// A safetensors file's float tensors, as f32.
fn read_safetensors(path: &Path, bytes: &[u8]) -> Result<BTreeMap<String, NamedTensor>> {
    use safetensors::{Dtype, SafeTensors};
    let st = SafeTensors::deserialize(bytes).map_err(|e| bad(path, e))?;
    let mut out = BTreeMap::new();
    for (name, view) in st.tensors() {
        let shape = view.shape().to_vec();
        let d = view.data();
        let values: Vec<f32> = match view.dtype() {
            Dtype::F32 => d
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
                .collect(),
            Dtype::F64 => d
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")) as f32)
                .collect(),
            Dtype::F16 => d
                .chunks_exact(2)
                .map(|c| half_to_f32(u16::from_le_bytes([c[0], c[1]])))
                .collect(),
            Dtype::BF16 => d
                .chunks_exact(2)
                .map(|c| f32::from_bits((u16::from_le_bytes([c[0], c[1]]) as u32) << 16))
                .collect(),
            _ => continue,
        };
        out.insert(name, NamedTensor { shape, values });
    }
    Ok(out)
}

/// IEEE half to f32 (safetensors' F16), subnormals and infinities kept.
fn half_to_f32(h: u16) -> f32 {
    let sign = ((h >> 15) as u32) << 31;
    let exp = ((h >> 10) & 0x1f) as i32;
    let frac = (h & 0x3ff) as u32;
    let bits = match exp {
        0 if frac == 0 => sign,
        0 => {
            let v = frac as f32 * 2f32.powi(-24);
            return if sign != 0 { -v } else { v };
        }
        31 => sign | 0x7f80_0000 | (frac << 13),
        e => sign | (((e - 15 + 127) as u32) << 23) | (frac << 13),
    };
    f32::from_bits(bits)
}

/// SHA-256 of `bytes`, lower-case hex.
fn sha256(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// The reader's multi-line messages on one line.
fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

#[cfg(test)]
mod tests {
    use super::half_to_f32;

    #[test]
    fn halves_convert_exactly() {
        assert_eq!(half_to_f32(0x3c00), 1.0);
        assert_eq!(half_to_f32(0xc000), -2.0);
        assert_eq!(half_to_f32(0x0001), 2f32.powi(-24));
        assert_eq!(half_to_f32(0x7bff), 65504.0);
        assert!(half_to_f32(0x7c00).is_infinite());
    }
}
