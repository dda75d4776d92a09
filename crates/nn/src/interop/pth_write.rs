//! Writing a state dict the way `torch.save` does (PyTorch >= 1.6): a zip
//! of uncompressed records under one folder, `data.pkl` holding an
//! `OrderedDict` of tensors rebuilt by `torch._utils._rebuild_tensor_v2`
//! from float storages whose bytes are the records `data/0`, `data/1`, ...
//! The pickle uses only what `torch.load(weights_only=True)` allows and
//! what [`super::pickle_check`] accepts, so pgrf reads its own files back.

use crate::error::NnError;
use crate::named::NamedTensor;
use std::io::Write;

/// Folder of the records inside the zip (torch names it after the file;
/// any name is read).
const ARCHIVE: &str = "archive";

/// The `.pth` bytes of `tensors` (contiguous f32, little-endian), in the
/// order given.
pub fn encode(tensors: &[(String, &NamedTensor)]) -> Result<Vec<u8>, NnError> {
    let mut pkl: Vec<u8> = vec![0x80, 0x02];
    global(&mut pkl, "collections", "OrderedDict");
    pkl.extend_from_slice(b")R(");
    for (i, (name, t)) in tensors.iter().enumerate() {
        let numel: usize = t.shape.iter().product();
        if numel != t.values.len() || numel > i32::MAX as usize {
            return Err(NnError::SizeMismatch(format!(
                "tensor {name}: {} values for shape {:?}",
                t.values.len(),
                t.shape
            )));
        }
        string(&mut pkl, name);
        global(&mut pkl, "torch._utils", "_rebuild_tensor_v2");
        pkl.extend_from_slice(b"((");
        string(&mut pkl, "storage");
        global(&mut pkl, "torch", "FloatStorage");
        string(&mut pkl, &i.to_string());
        string(&mut pkl, "cpu");
        int(&mut pkl, numel);
        pkl.extend_from_slice(b"tQ");
        int(&mut pkl, 0);
        pkl.push(b'(');
        for &d in &t.shape {
            int(&mut pkl, d);
        }
        pkl.push(b't');
        pkl.push(b'(');
        let mut stride = vec![1usize; t.shape.len()];
        for k in (0..t.shape.len().saturating_sub(1)).rev() {
            stride[k] = stride[k + 1] * t.shape[k + 1];
        }
        for s in stride {
            int(&mut pkl, s);
        }
        pkl.push(b't');
        pkl.push(0x89);
        global(&mut pkl, "collections", "OrderedDict");
        pkl.extend_from_slice(b")RtR");
    }
    pkl.extend_from_slice(b"u.");

    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let opts = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Stored)
        .last_modified_time(zip::DateTime::default());
    let zipped = |e: &dyn std::fmt::Display| NnError::Invalid(e.to_string());
    let mut put = |name: &str, bytes: &[u8]| -> Result<(), NnError> {
        zip.start_file(format!("{ARCHIVE}/{name}"), opts)
            .map_err(|e| zipped(&e))?;
        zip.write_all(bytes).map_err(|e| zipped(&e))
    };
    put("data.pkl", &pkl)?;
    put("byteorder", b"little")?;
    for (i, (_, t)) in tensors.iter().enumerate() {
        let bytes: Vec<u8> = t.values.iter().flat_map(|v| v.to_le_bytes()).collect();
        put(&format!("data/{i}"), &bytes)?;
    }
    put("version", b"3\n")?;
    let out = zip.finish().map_err(|e| zipped(&e))?;
    Ok(out.into_inner())
}

/// GLOBAL `module.name`.
fn global(p: &mut Vec<u8>, module: &str, name: &str) {
    p.push(b'c');
    p.extend_from_slice(module.as_bytes());
    p.push(b'\n');
    p.extend_from_slice(name.as_bytes());
    p.push(b'\n');
}

/// BINUNICODE.
fn string(p: &mut Vec<u8>, s: &str) {
    p.push(b'X');
    p.extend_from_slice(&(s.len() as u32).to_le_bytes());
    p.extend_from_slice(s.as_bytes());
}

/// BININT (every int here is a size below 2^31).
fn int(p: &mut Vec<u8>, v: usize) {
    p.push(b'J');
    p.extend_from_slice(&(v as i32).to_le_bytes());
}
