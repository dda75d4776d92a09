//! NumPy `.npy` files of packed planes: how an evaluation hands its captures
//! to a method outside pgrf (a Python reference such as VST + BM3D) and
//! reads that method's restorations back, so both are measured by the same
//! code as pgrf's models.
//!
//! Only what that exchange needs: format version 1.0 or 2.0, little-endian
//! float32 (`<f4`) or float64 (`<f8`, read only), C order, three
//! dimensions. The header and the data size are checked against the file's
//! length before anything is allocated.

use ndarray::{Array3, ArrayView3};
use std::path::Path;

const MAGIC: &[u8; 6] = b"\x93NUMPY";
/// The largest header read (NumPy writes well under 1 KiB).
const MAX_HEADER: usize = 64 * 1024;

/// The bytes of `a` as a version 1.0 `.npy` file of `<f4`, C order.
pub fn encode(a: ArrayView3<f32>) -> Vec<u8> {
    let (c, h, w) = a.dim();
    let dict = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({c}, {h}, {w}), }}");
    // Magic (6) + version (2) + header length (2) + dict + padding + '\n'
    // is a multiple of 64.
    let unpadded = 10 + dict.len() + 1;
    let pad = (64 - unpadded % 64) % 64;
    let header_len = dict.len() + pad + 1;
    let mut out = Vec::with_capacity(10 + header_len + 4 * a.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&(header_len as u16).to_le_bytes());
    out.extend_from_slice(dict.as_bytes());
    out.extend(std::iter::repeat_n(b' ', pad));
    out.push(b'\n');
    for v in a.iter() {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// Write `a` to `path` atomically.
pub fn write(path: &Path, a: ArrayView3<f32>) -> Result<(), String> {
    pgrf_core::write_atomic(path, &encode(a)).map_err(|e| format!("{}: {e}", path.display()))
}

/// The value of `key` in a NumPy header dict (text up to the next top-level
/// comma or closing brace; the shape's tuple is kept whole).
fn field<'a>(dict: &'a str, key: &str) -> Option<&'a str> {
    let at = dict.find(&format!("'{key}'"))? + key.len() + 2;
    let rest = dict[at..].trim_start().strip_prefix(':')?.trim_start();
    let end = if rest.starts_with('(') {
        rest.find(')')? + 1
    } else {
        rest.find([',', '}'])?
    };
    Some(rest[..end].trim())
}

/// Parse `.npy` bytes into a three-dimensional f32 array; `name` names them
/// in errors.
pub fn decode(name: &str, bytes: &[u8]) -> Result<Array3<f32>, String> {
    let bad = |why: String| format!("{name}: {why}");
    if bytes.len() < 10 || &bytes[..6] != MAGIC {
        return Err(bad("not a NumPy .npy file".into()));
    }
    let (header_len, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(bad(format!(".npy format version {v} is not supported"))),
    };
    if header_len > MAX_HEADER || start + header_len > bytes.len() {
        return Err(bad(format!(
            "header of {header_len} bytes does not fit the file"
        )));
    }
    let dict = std::str::from_utf8(&bytes[start..start + header_len])
        .map_err(|_| bad("header is not text".into()))?;
    let descr = field(dict, "descr").ok_or_else(|| bad("header has no 'descr'".into()))?;
    let size = match descr.trim_matches(['\'', '"']) {
        "<f4" => 4,
        "<f8" => 8,
        d => {
            return Err(bad(format!(
                "dtype {d} (expected little-endian float32 or float64)"
            )))
        }
    };
    if field(dict, "fortran_order") != Some("False") {
        return Err(bad("Fortran-ordered arrays are not supported".into()));
    }
    let shape_text = field(dict, "shape").ok_or_else(|| bad("header has no 'shape'".into()))?;
    let dims: Vec<usize> = shape_text
        .trim_matches(['(', ')'])
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| bad(format!("shape {shape_text} is not a tuple of sizes")))?;
    let [c, h, w] = dims[..] else {
        return Err(bad(format!(
            "shape {shape_text}: expected three dimensions (4, H, W)"
        )));
    };
    let data = &bytes[start + header_len..];
    let count = c
        .checked_mul(h)
        .and_then(|n| n.checked_mul(w))
        .filter(|n| n.checked_mul(size) == Some(data.len()))
        .ok_or_else(|| {
            bad(format!(
                "shape {shape_text} of {size}-byte values does not match the {} data bytes",
                data.len()
            ))
        })?;
    let values: Vec<f32> = if size == 4 {
        data.chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect()
    } else {
        data.chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")) as f32)
            .collect()
    };
    debug_assert_eq!(values.len(), count);
    Array3::from_shape_vec((c, h, w), values).map_err(|e| bad(e.to_string()))
}

/// Read a `.npy` file of at most `max_bytes` (refused before reading when
/// larger).
pub fn read(path: &Path, max_bytes: u64) -> Result<Array3<f32>, String> {
    let name = path.display().to_string();
    let len = std::fs::metadata(path)
        .map_err(|e| format!("{name}: {e}"))?
        .len();
    if len > max_bytes {
        return Err(format!(
            "{name}: {len} bytes, more than the {max_bytes} this case's planes can take"
        ));
    }
    let bytes = std::fs::read(path).map_err(|e| format!("{name}: {e}"))?;
    decode(&name, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_matches_numpys_layout() {
        let a = Array3::from_shape_fn((4, 3, 5), |(c, y, x)| {
            c as f32 - 0.25 * y as f32 + x as f32 * 1e-3
        });
        let bytes = encode(a.view());
        // NumPy 1.x/2.x writes exactly this header for np.save of a (4, 3, 5)
        // float32 array: 118 bytes padded to 128 with the data after it.
        assert_eq!(&bytes[..10], b"\x93NUMPY\x01\x00v\x00");
        assert_eq!(
            std::str::from_utf8(&bytes[10..128]).unwrap().trim_end(),
            "{'descr': '<f4', 'fortran_order': False, 'shape': (4, 3, 5), }"
        );
        assert_eq!(bytes.len(), 128 + 4 * 60);
        assert_eq!(decode("a", &bytes).unwrap(), a);
    }

    /// A version 1.0 header for `descr` and `shape`, padded as NumPy pads.
    fn header(descr: &str, shape: &str) -> Vec<u8> {
        let dict = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
        let pad = (64 - (10 + dict.len() + 1) % 64) % 64;
        let mut h = b"\x93NUMPY\x01\x00".to_vec();
        h.extend_from_slice(&((dict.len() + pad + 1) as u16).to_le_bytes());
        h.extend_from_slice(dict.as_bytes());
        h.extend(std::iter::repeat_n(b' ', pad));
        h.push(b'\n');
        h
    }

    #[test]
    fn reads_float64_and_refuses_what_it_cannot_take() {
        let data: Vec<u8> = [0.5f64, -2.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let file = |descr: &str, shape: &str, data: &[u8]| {
            let mut f = header(descr, shape);
            f.extend_from_slice(data);
            f
        };
        let f8 = file("<f8", "(1, 1, 2)", &data);
        assert_eq!(
            decode("f8", &f8).unwrap().into_raw_vec_and_offset().0,
            vec![0.5, -2.0]
        );
        // One value short, one too many, big-endian, two dimensions, a shape
        // far larger than the data, junk, nothing.
        assert!(decode("short", &f8[..f8.len() - 8]).is_err());
        let mut long = f8.clone();
        long.extend_from_slice(&[0; 8]);
        assert!(decode("long", &long).is_err());
        assert!(decode("be", &file(">f8", "(1, 1, 2)", &data))
            .unwrap_err()
            .contains("dtype"));
        assert!(decode("2d", &file("<f8", "(1, 2)", &data))
            .unwrap_err()
            .contains("three dimensions"));
        let huge = file("<f4", "(9999999999, 99999, 9)", &data);
        assert!(decode("huge", &huge)
            .unwrap_err()
            .contains("does not match"));
        let overflow = file("<f4", "(18446744073709551615, 2, 2)", &data);
        assert!(decode("overflow", &overflow).is_err());
        assert!(decode("junk", b"PK\x03\x04 not numpy").is_err());
        assert!(decode("empty", b"").is_err());
    }
}
