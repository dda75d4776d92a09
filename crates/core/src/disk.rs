//! Room on a file system: what a command that writes many files checks
//! before it starts, so that an absurd count is refused in one line with
//! the figures instead of filling the disk.

use std::path::Path;

/// What a file system has free for an unprivileged user.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Room {
    /// Bytes free.
    pub bytes: u64,
    /// Files (inodes) free; `None` where the file system sets no limit
    /// (btrfs reports none).
    pub files: Option<u64>,
}

/// The room on the file system `path` is (or would be) on: that of its
/// nearest existing ancestor. `None` where it cannot be read.
pub fn room(path: &Path) -> Option<Room> {
    let mut p = path;
    while !p.exists() {
        p = match p.parent() {
            Some(q) if !q.as_os_str().is_empty() => q,
            _ => Path::new("."),
        };
    }
    statvfs(p)
}

// The counts are u64 on 64-bit Linux, u32 on 32-bit: `u64::from` serves both.
#[allow(unsafe_code, clippy::useless_conversion)]
fn statvfs(p: &Path) -> Option<Room> {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        use std::os::unix::ffi::OsStrExt;
        let c = std::ffi::CString::new(p.as_os_str().as_bytes()).ok()?;
        let mut s = std::mem::MaybeUninit::<libc::statvfs>::zeroed();
        // SAFETY: `c` is a NUL-terminated path and `s` points at writable
        // memory of the structure's size, which statvfs fills on success
        // (zeroed before, so it is initialised either way).
        let r = unsafe { libc::statvfs(c.as_ptr(), s.as_mut_ptr()) };
        if r != 0 {
            return None;
        }
        // SAFETY: zero-initialised above and filled by statvfs.
        let s = unsafe { s.assume_init() };
        Some(Room {
            bytes: u64::from(s.f_bavail).saturating_mul(u64::from(s.f_frsize)),
            files: (s.f_files != 0).then_some(u64::from(s.f_favail)),
        })
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        let _ = p;
        None
    }
}

/// Writes the file system cannot take: what they are, their size and
/// count, and the room there is, so that a caller can size what would fit.
/// The message starts with `what` and gives both figures.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{what} would write {files} files, about {}; the file system of {} has {}{} free", size(*bytes), at.display(), size(*room_bytes as f64), room_files.map(|f| format!(" and room for {f} files")).unwrap_or_default())]
pub struct NoRoom {
    /// The writes, in the caller's words ("--scenes 1000").
    pub what: String,
    /// Bytes they take in all.
    pub bytes: f64,
    /// Files they make.
    pub files: u64,
    /// Where they go.
    pub at: std::path::PathBuf,
    /// Free bytes there.
    pub room_bytes: u64,
    /// Free file slots there, when the file system counts them.
    pub room_files: Option<u64>,
}

/// Refuse to write `files` files of about `bytes` in all under `at` when its
/// file system has less room (no limit where the room cannot be read).
pub fn check_room(what: &str, bytes: f64, files: u64, at: &Path) -> Result<(), NoRoom> {
    let Some(room) = room(at) else {
        return Ok(());
    };
    let bytes_fit = bytes.is_finite() && bytes <= room.bytes as f64;
    let files_fit = room.files.is_none_or(|f| files <= f);
    if bytes_fit && files_fit {
        return Ok(());
    }
    Err(NoRoom {
        what: what.to_string(),
        bytes,
        files,
        at: at.to_path_buf(),
        room_bytes: room.bytes,
        room_files: room.files,
    })
}

/// `b` bytes in words: "3.2 GB", "2.1 PB".
fn size(b: f64) -> String {
    let units = ["bytes", "kB", "MB", "GB", "TB", "PB", "EB"];
    let mut v = b;
    let mut u = 0;
    while v >= 1000.0 && u + 1 < units.len() {
        v /= 1000.0;
        u += 1;
    }
    if u == 0 {
        format!("{v:.0} bytes")
    } else {
        format!("{v:.1} {}", units[u])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_room_of_a_new_path_is_its_folders() {
        let dir = std::env::temp_dir();
        let here = room(&dir).expect("statvfs works on Linux");
        assert!(here.bytes > 0);
        let deep = dir.join("pgrf-no-such-folder/a/b/c.dng");
        assert_eq!(room(&deep).map(|r| r.bytes > 0), Some(true));
    }

    #[test]
    fn more_than_the_disk_is_refused_with_the_figures() {
        let dir = std::env::temp_dir();
        assert_eq!(check_room("a small write", 1000.0, 1, &dir), Ok(()));
        let e = check_room("--scenes 1000000000", 2.1e15, 16_000_000_000, &dir).unwrap_err();
        assert_eq!(
            (e.files, e.bytes, e.at.as_path()),
            (16_000_000_000, 2.1e15, dir.as_path())
        );
        let e = e.to_string();
        assert!(
            e.starts_with("--scenes 1000000000 would write 16000000000 files, about 2.1 PB; the file system of"),
            "{e}"
        );
        assert_eq!(size(999.0), "999 bytes");
        assert_eq!(size(3.21e9), "3.2 GB");
    }
}
