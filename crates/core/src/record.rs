//! pgrf's file format for named f32 tensors with a JSON record: a safetensors
//! file whose metadata key `"pgrf"` holds the record. Calibration files,
//! virtual-sensor truth and weight files are all written and read here, so
//! any tool that reads safetensors (numpy, PyTorch) can open them and pgrf
//! reads them one way.

use safetensors::tensor::{Dtype, SafeTensors, TensorView};
use std::collections::{BTreeMap, HashMap};

/// Metadata key holding pgrf's JSON record.
pub(crate) const META_KEY: &str = "pgrf";

/// One named tensor: row-major f32 values and their shape.
#[derive(Clone, Debug, PartialEq)]
pub struct Tensor {
    /// Dimensions, outermost first.
    pub shape: Vec<usize>,
    /// `shape.iter().product()` values in row-major order.
    pub values: Vec<f32>,
}

/// A decoded file: the JSON record's text and the tensors by name.
#[derive(Clone, Debug)]
pub struct Record {
    /// The JSON record under the metadata key `"pgrf"`, as written.
    pub meta: String,
    /// Every tensor of the file.
    pub tensors: BTreeMap<String, Tensor>,
}

/// Why bytes are not a pgrf record file (one line each; callers add the path).
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// Not parseable as safetensors at all.
    #[error("not a safetensors file ({0})")]
    NotSafetensors(String),
    /// A safetensors file without pgrf's record.
    #[error("no pgrf record in the metadata")]
    NoRecord,
    /// A tensor that is not f32, or whose bytes do not match its shape.
    #[error("tensor {name} {reason}")]
    BadTensor {
        /// The tensor's name.
        name: String,
        /// What is wrong with it.
        reason: String,
    },
}

type Result<T> = std::result::Result<T, RecordError>;

/// Serialise `tensors` (name, shape, values) and the JSON record `meta`.
/// Tensors are stored as little-endian f32 in safetensors' own order.
pub fn encode<'a>(
    tensors: impl IntoIterator<Item = (&'a str, &'a [usize], &'a [f32])>,
    meta: &str,
) -> Result<Vec<u8>> {
    let owned: Vec<(String, Vec<u8>, Vec<usize>)> = tensors
        .into_iter()
        .map(|(name, shape, values)| {
            let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
            (name.to_string(), bytes, shape.to_vec())
        })
        .collect();
    let views = owned
        .iter()
        .map(|(n, b, s)| {
            TensorView::new(Dtype::F32, s.clone(), b)
                .map(|v| (n.clone(), v))
                .map_err(|e| RecordError::BadTensor {
                    name: n.clone(),
                    reason: e.to_string(),
                })
        })
        .collect::<Result<Vec<_>>>()?;
    let mut info = HashMap::new();
    info.insert(META_KEY.to_string(), meta.to_string());
    safetensors::tensor::serialize(views, Some(info))
        .map_err(|e| RecordError::NotSafetensors(e.to_string()))
}

/// The JSON record of a file, without decoding its tensors.
pub fn read_meta(bytes: &[u8]) -> Result<String> {
    let (_, header) = SafeTensors::read_metadata(bytes)
        .map_err(|e| RecordError::NotSafetensors(e.to_string()))?;
    header
        .metadata()
        .as_ref()
        .and_then(|m| m.get(META_KEY))
        .cloned()
        .ok_or(RecordError::NoRecord)
}

/// Decode a whole file: its record and every tensor, which must be f32.
pub fn decode(bytes: &[u8]) -> Result<Record> {
    let meta = read_meta(bytes)?;
    let st =
        SafeTensors::deserialize(bytes).map_err(|e| RecordError::NotSafetensors(e.to_string()))?;
    let mut tensors = BTreeMap::new();
    for (name, view) in st.tensors() {
        if view.dtype() != Dtype::F32 {
            return Err(RecordError::BadTensor {
                reason: format!("is {:?}, expected F32", view.dtype()),
                name,
            });
        }
        let values: Vec<f32> = view
            .data()
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        tensors.insert(
            name,
            Tensor {
                shape: view.shape().to_vec(),
                values,
            },
        );
    }
    Ok(Record { meta, tensors })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_keeps_values_shapes_and_record() {
        let a: Vec<f32> = (0..24).map(|i| i as f32 * 0.5 - 3.0).collect();
        let b = vec![f32::MIN_POSITIVE, -1.25, 7.0];
        let bytes = encode(
            [("a", &[2, 3, 4][..], &a[..]), ("b", &[3][..], &b[..])],
            "{\"k\":1}",
        )
        .unwrap();
        let r = decode(&bytes).unwrap();
        assert_eq!(r.meta, "{\"k\":1}");
        assert_eq!(r.tensors["a"].shape, vec![2, 3, 4]);
        assert_eq!(r.tensors["a"].values, a);
        assert_eq!(r.tensors["b"].values, b);
        // Same input, same bytes.
        let again = encode(
            [("a", &[2, 3, 4][..], &a[..]), ("b", &[3][..], &b[..])],
            "{\"k\":1}",
        )
        .unwrap();
        assert_eq!(bytes, again);
    }

    #[test]
    fn refusals_name_the_problem() {
        assert!(matches!(
            decode(b"not a tensor file"),
            Err(RecordError::NotSafetensors(_))
        ));
        let plain = safetensors::tensor::serialize(
            Vec::<(String, TensorView)>::new(),
            None::<HashMap<String, String>>,
        )
        .unwrap();
        assert!(matches!(decode(&plain), Err(RecordError::NoRecord)));
        let wrong = encode([("a", &[2, 2][..], &[1.0f32, 2.0, 3.0][..])], "{}");
        assert!(matches!(wrong, Err(RecordError::BadTensor { .. })));
    }
}
