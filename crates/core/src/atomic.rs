//! Atomic file writes: write a sibling temporary file, flush it to disk, then
//! rename it over the target. An interrupted run leaves either the old file or
//! the new one, never half of one. Shared by every crate that writes outputs
//! (DNGs, PNGs, calibration files, weights, checkpoints, reports).

use std::io::Write;
use std::path::{Path, PathBuf};

/// A file that could not be written; renders as one line naming it.
#[derive(Debug, thiserror::Error)]
#[error("{}: cannot write: {reason}", path.display())]
pub struct WriteError {
    /// The file that was to be written.
    pub(crate) path: PathBuf,
    /// Why not, on one line.
    pub(crate) reason: String,
}

impl WriteError {
    fn new(path: &Path, reason: impl Into<String>) -> Self {
        let reason: String = reason.into();
        WriteError {
            path: path.to_path_buf(),
            reason: reason.lines().next().unwrap_or_default().to_string(),
        }
    }
}

type Result<T> = std::result::Result<T, WriteError>;

/// Write `bytes` to `path` atomically.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic_with(path, |f| f.write_all(bytes))
}

/// Atomically create `path` from whatever `fill` writes into the temp file.
pub(crate) fn write_atomic_with(
    path: &Path,
    fill: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> Result<()> {
    let dir = parent_dir(path);
    if !dir.is_dir() {
        return Err(WriteError::new(
            path,
            format!("folder '{}' does not exist", dir.display()),
        ));
    }
    if path.is_dir() {
        return Err(WriteError::new(path, "is a directory"));
    }
    let tmp = temp_sibling(path);
    let result = (|| -> std::io::Result<()> {
        let file = std::fs::File::create(&tmp)?;
        let mut w = std::io::BufWriter::new(file);
        fill(&mut w)?;
        let file = w.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(WriteError::new(path, e.to_string()));
    }
    Ok(())
}

fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Hidden name in the same folder (rename is atomic only within a file system),
/// unique per process and call so parallel writers never share one.
fn temp_sibling(path: &Path) -> PathBuf {
    use std::sync::atomic::{AtomicU64, Ordering};
    static N: AtomicU64 = AtomicU64::new(0);
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = format!(
        ".{name}.{}.{}.part",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    );
    parent_dir(path).join(tmp)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("pgrf-atomic-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn writes_and_replaces() {
        let d = scratch("replace");
        let p = d.join("a.bin");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two!").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two!");
        assert_eq!(
            std::fs::read_dir(&d).unwrap().count(),
            1,
            "no temp file left behind"
        );
    }

    #[test]
    fn failed_fill_leaves_old_file_and_no_temp() {
        let d = scratch("fail");
        let p = d.join("a.bin");
        write_atomic(&p, b"old").unwrap();
        let err = write_atomic_with(&p, |w| {
            w.write_all(b"half")?;
            Err(std::io::Error::other("interrupted"))
        })
        .unwrap_err();
        assert!(err.to_string().contains("interrupted"));
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1);
    }

    #[test]
    fn missing_folder_is_a_clear_error() {
        let d = scratch("missing");
        let err = write_atomic(&d.join("nope/x.dng"), b"x")
            .unwrap_err()
            .to_string();
        assert!(err.contains("does not exist"), "{err}");
    }
}
