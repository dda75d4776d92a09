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
    remove_stale_parts(&dir);
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

/// When this process first wrote (an upper bound on its start): a part file
/// last modified before it belongs to a run that ended before this one.
fn first_write() -> std::time::SystemTime {
    static T: std::sync::OnceLock<std::time::SystemTime> = std::sync::OnceLock::new();
    *T.get_or_init(std::time::SystemTime::now)
}

/// The process id in a name of [`temp_sibling`]'s form `.NAME.PID.N.part`,
/// or None for any other name (a user's own hidden files are never touched).
fn part_owner(name: &str) -> Option<u32> {
    let inner = name.strip_prefix('.')?.strip_suffix(".part")?;
    let mut fields = inner.rsplitn(3, '.');
    fields.next()?.parse::<u64>().ok()?;
    let pid = fields.next()?.parse::<u32>().ok()?;
    fields.next().filter(|n| !n.is_empty())?;
    Some(pid)
}

/// Whether process `pid` is running. Where that cannot be known (no /proc)
/// the answer is "yes", so only the age rule applies.
fn alive(pid: u32) -> bool {
    let proc = Path::new("/proc");
    !proc.is_dir() || proc.join(pid.to_string()).exists()
}

/// Remove the temporary files that killed pgrf runs left in `dir`: names of
/// pgrf's own form whose writer is no longer running and that were last
/// modified before this process started writing. A SIGKILL between create
/// and rename leaves such a file (up to a checkpoint's size); nothing else
/// would ever remove it. Failures are ignored: cleaning is a courtesy, never
/// a reason for a write to fail.
///
/// Once per folder and process: only files older than this process's first
/// write qualify, and none can appear later, so a second look at the same
/// folder (a batch writing hundreds of outputs, a run checkpointing every
/// few minutes) would only list it again for nothing.
fn remove_stale_parts(dir: &Path) {
    static CLEANED: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());
    let key = std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf());
    {
        let mut cleaned = CLEANED.lock().unwrap_or_else(|e| e.into_inner());
        if cleaned.contains(&key) {
            return;
        }
        cleaned.push(key);
    }
    let started = first_write();
    let me = std::process::id();
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(pid) = name.to_str().and_then(part_owner) else {
            continue;
        };
        if pid == me || alive(pid) {
            continue;
        }
        let old = entry
            .metadata()
            .ok()
            .filter(|m| m.is_file())
            .and_then(|m| m.modified().ok())
            .is_some_and(|t| t < started);
        if old {
            let _ = std::fs::remove_file(entry.path());
        }
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
        std::fs::remove_dir_all(&d).unwrap();
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
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn stale_parts_of_dead_runs_are_removed_and_nothing_else() {
        let d = scratch("stale");
        first_write();
        // A pid above Linux's maximum (2^22) is never a running process.
        let dead = d.join(".x.dng.4194999.0.part");
        let mine = d.join(format!(".y.dng.{}.7.part", std::process::id()));
        let user = [
            ".notes.part",
            ".a.b.part",
            "x.4194999.0.part",
            ".4194999.0.part",
        ];
        std::fs::write(&dead, b"half a file").unwrap();
        std::fs::write(&mine, b"being written").unwrap();
        for u in user {
            std::fs::write(d.join(u), b"keep").unwrap();
        }
        // Modified before this process's first write: set the clock back.
        let past = std::time::SystemTime::now() - std::time::Duration::from_secs(3600);
        for p in [&dead, &mine] {
            std::fs::File::options()
                .write(true)
                .open(p)
                .unwrap()
                .set_modified(past)
                .unwrap();
        }
        write_atomic(&d.join("out.bin"), b"x").unwrap();
        assert!(!dead.exists(), "a dead run's part file is removed");
        assert!(mine.exists(), "this process's own part file stays");
        for u in user {
            assert!(d.join(u).exists(), "{u} is not pgrf's and stays");
        }
        assert_eq!(part_owner(".x.dng.12.3.part"), Some(12));
        assert_eq!(part_owner(".x.12.3.part"), Some(12));
        assert_eq!(part_owner(".12.3.part"), None);
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn missing_folder_is_a_clear_error() {
        let d = scratch("missing");
        let err = write_atomic(&d.join("nope/x.dng"), b"x")
            .unwrap_err()
            .to_string();
        assert!(err.contains("does not exist"), "{err}");
        std::fs::remove_dir_all(&d).unwrap();
    }
}
