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

/// Why a `.npy` file could not be read or written; every variant names the
/// file (`file`) and renders as one line. A caller can tell a file that is
/// not NumPy's, one of another dtype or shape, and one that could not be
/// read or written at all.
#[derive(Debug, thiserror::Error)]
pub enum NpyError {
    /// Not a `.npy` file: no magic string.
    #[error("{file}: not a NumPy .npy file")]
    NotNpy {
        /// The file.
        file: String,
    },
    /// A format version other than 1.0, 2.0 or 3.0.
    #[error("{file}: .npy format version {version} is not supported")]
    Version {
        /// The file.
        file: String,
        /// Its major version.
        version: u8,
    },
    /// A header that does not fit the file, is not text, or lacks a key.
    #[error("{file}: {fault}")]
    Header {
        /// The file.
        file: String,
        /// What is wrong with the header.
        fault: HeaderFault,
    },
    /// Values that are not little-endian float32 or float64.
    #[error("{file}: dtype {dtype} (expected little-endian float32 or float64)")]
    Dtype {
        /// The file.
        file: String,
        /// The header's `descr`.
        dtype: String,
    },
    /// A Fortran-ordered (column-major) array.
    #[error("{file}: Fortran-ordered arrays are not supported")]
    FortranOrder {
        /// The file.
        file: String,
    },
    /// A shape that is not three sizes, or that the data do not fill.
    #[error("{file}: shape {shape}{fault}")]
    Shape {
        /// The file.
        file: String,
        /// The header's shape, as written.
        shape: String,
        /// What is wrong with it.
        fault: ShapeFault,
    },
    /// A file larger than the planes it is read for can be.
    #[error("{file}: {len} bytes, more than the {max} this case's planes can take")]
    TooLarge {
        /// The file.
        file: String,
        /// Its size, bytes.
        len: u64,
        /// The most accepted, bytes.
        max: u64,
    },
    /// The file could not be read.
    #[error("{file}: {error}")]
    Read {
        /// The file.
        file: String,
        /// The operating system's error.
        error: std::io::Error,
    },
    /// The file could not be written.
    #[error("{file}: {error}")]
    Write {
        /// The file.
        file: String,
        /// Why not.
        error: pgrf_core::WriteError,
    },
}

/// What is wrong with a `.npy` header.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum HeaderFault {
    /// A header length beyond the file or 64 KiB (NumPy writes well under
    /// 1 KiB).
    #[error("header of {0} bytes does not fit the file")]
    Length(usize),
    /// A header that is not UTF-8.
    #[error("header is not text")]
    NotText,
    /// A header without a key the file needs.
    #[error("header has no '{0}'")]
    Missing(&'static str),
}

/// What is wrong with a `.npy` shape (the text after `shape (..)`).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ShapeFault {
    /// Not a tuple of sizes.
    #[error(" is not a tuple of sizes")]
    NotSizes,
    /// Not three dimensions.
    #[error(": expected three dimensions (4, H, W)")]
    NotThree,
    /// A value count other than the data bytes hold.
    #[error(" of {size}-byte values does not match the {bytes} data bytes")]
    DataSize {
        /// Bytes per value.
        size: usize,
        /// The data's bytes.
        bytes: usize,
    },
}

/// Write `a` to `path` atomically.
pub fn write(path: &Path, a: ArrayView3<f32>) -> Result<(), NpyError> {
    pgrf_core::write_atomic(path, &encode(a)).map_err(|error| NpyError::Write {
        file: path.display().to_string(),
        error,
    })
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

/// The header dict of `.npy` bytes (magic, version and length checked)
/// and where the data start; `name` names the bytes in errors.
fn header_dict<'a>(name: &str, bytes: &'a [u8]) -> Result<(&'a str, usize), NpyError> {
    let file = || name.to_string();
    if bytes.len() < 10 || &bytes[..6] != MAGIC {
        return Err(NpyError::NotNpy { file: file() });
    }
    let header = |fault| NpyError::Header {
        file: file(),
        fault,
    };
    let (header_len, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        version => {
            return Err(NpyError::Version {
                file: file(),
                version,
            })
        }
    };
    if header_len > MAX_HEADER || start + header_len > bytes.len() {
        return Err(header(HeaderFault::Length(header_len)));
    }
    let dict = std::str::from_utf8(&bytes[start..start + header_len])
        .map_err(|_| header(HeaderFault::NotText))?;
    Ok((dict, start + header_len))
}

/// Parse `.npy` bytes into a three-dimensional f32 array; `name` names them
/// in errors.
pub fn decode(name: &str, bytes: &[u8]) -> Result<Array3<f32>, NpyError> {
    let file = || name.to_string();
    let (dict, data_start) = header_dict(name, bytes)?;
    let header = |fault| NpyError::Header {
        file: file(),
        fault,
    };
    let descr = field(dict, "descr").ok_or(header(HeaderFault::Missing("descr")))?;
    let size = match descr.trim_matches(['\'', '"']) {
        "<f4" => 4,
        "<f8" => 8,
        d => {
            return Err(NpyError::Dtype {
                file: file(),
                dtype: d.to_string(),
            })
        }
    };
    if field(dict, "fortran_order") != Some("False") {
        return Err(NpyError::FortranOrder { file: file() });
    }
    let shape_text = field(dict, "shape").ok_or(header(HeaderFault::Missing("shape")))?;
    let shape = |fault| NpyError::Shape {
        file: file(),
        shape: shape_text.to_string(),
        fault,
    };
    let dims: Vec<usize> = shape_text
        .trim_matches(['(', ')'])
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| shape(ShapeFault::NotSizes))?;
    let [c, h, w] = dims[..] else {
        return Err(shape(ShapeFault::NotThree));
    };
    let data = &bytes[data_start..];
    c.checked_mul(h)
        .and_then(|n| n.checked_mul(w))
        .filter(|n| n.checked_mul(size) == Some(data.len()))
        .ok_or_else(|| {
            shape(ShapeFault::DataSize {
                size,
                bytes: data.len(),
            })
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
    Ok(Array3::from_shape_vec((c, h, w), values).expect("the data fill the checked shape"))
}

/// Read a `.npy` file of at most `max_bytes` (refused before reading when
/// larger).
pub fn read(path: &Path, max_bytes: u64) -> Result<Array3<f32>, NpyError> {
    let file = || path.display().to_string();
    let read = |error| NpyError::Read {
        file: file(),
        error,
    };
    let len = std::fs::metadata(path).map_err(read)?.len();
    if len > max_bytes {
        return Err(NpyError::TooLarge {
            file: file(),
            len,
            max: max_bytes,
        });
    }
    let bytes = std::fs::read(path).map_err(read)?;
    decode(&file(), &bytes)
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
        let be = decode("be", &file(">f8", "(1, 1, 2)", &data)).unwrap_err();
        assert!(matches!(&be, NpyError::Dtype { dtype, .. } if dtype == ">f8"));
        assert_eq!(
            be.to_string(),
            "be: dtype >f8 (expected little-endian float32 or float64)"
        );
        let flat = decode("2d", &file("<f8", "(1, 2)", &data)).unwrap_err();
        assert_eq!(
            flat.to_string(),
            "2d: shape (1, 2): expected three dimensions (4, H, W)"
        );
        let huge = file("<f4", "(9999999999, 99999, 9)", &data);
        let e = decode("huge", &huge).unwrap_err();
        assert!(
            matches!(
                &e,
                NpyError::Shape {
                    fault: ShapeFault::DataSize { size: 4, bytes: 16 },
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("does not match"), "{e}");
        let overflow = file("<f4", "(18446744073709551615, 2, 2)", &data);
        assert!(decode("overflow", &overflow).is_err());
        assert_eq!(
            decode("junk", b"PK\x03\x04 not numpy")
                .unwrap_err()
                .to_string(),
            "junk: not a NumPy .npy file"
        );
        assert!(decode("empty", b"").is_err());
    }
}
