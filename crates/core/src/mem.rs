//! The process's memory figures as Linux reports them: what is available for
//! new allocations (to size tiles and refuse work that cannot fit) and the
//! peak resident set (reported by runs and benchmarks).

fn kib_field(file: &str, key: &str) -> Option<u64> {
    let text = std::fs::read_to_string(file).ok()?;
    text.lines()
        .find(|l| l.starts_with(key))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|kb| kb.parse::<u64>().ok())
        .map(|kb| kb * 1024)
}

/// Memory available for new allocations, in bytes: Linux's `MemAvailable`,
/// or less where the process's address space is capped (`ulimit -v`,
/// RLIMIT_AS) and the cap minus what it has mapped is smaller, since an
/// allocation past the cap aborts the process however much RAM is free.
/// None where neither can be read.
pub fn available_memory() -> Option<u64> {
    let ram = kib_field("/proc/meminfo", "MemAvailable:");
    let capped = address_space_left();
    match (ram, capped) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// The soft RLIMIT_AS minus the process's mapped size (`VmSize`), in bytes;
/// None when unlimited or unreadable (read from /proc, no system call).
fn address_space_left() -> Option<u64> {
    let limits = std::fs::read_to_string("/proc/self/limits").ok()?;
    let soft = limits
        .lines()
        .find(|l| l.starts_with("Max address space"))?
        .trim_start_matches("Max address space")
        .split_whitespace()
        .next()?
        .parse::<u64>()
        .ok()?;
    let mapped = kib_field("/proc/self/status", "VmSize:")?;
    Some(soft.saturating_sub(mapped))
}

/// Bytes in a GiB.
const GIB: f64 = 1024.0 * 1024.0 * 1024.0;

/// Work whose memory cannot be had: what it is, the bytes it needs and
/// those available, so that a caller can size what would fit (a smaller
/// tile, fewer pairs). The message starts with `what` and gives both
/// figures in GiB.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{what} needs about {:.1} GiB of memory, {:.1} GiB is available", need / GIB, available / GIB)]
pub struct NoMemory {
    /// The work, in the caller's words ("--tile 512").
    pub what: String,
    /// Bytes it needs (may be infinite: a size that overflows).
    pub need: f64,
    /// Bytes the OS says are available.
    pub available: f64,
}

/// Refuse work whose memory cannot be had: `need` bytes against what the
/// OS says is available (no limit where that cannot be read).
pub fn check_fits(what: &str, need: f64) -> Result<(), NoMemory> {
    let available = available_memory().map_or(f64::INFINITY, |b| b as f64);
    if need.is_finite() && need <= available {
        return Ok(());
    }
    Err(NoMemory {
        what: what.to_string(),
        need,
        available,
    })
}

/// Peak resident memory of this process so far, in bytes (Linux's `VmHWM`);
/// None where it cannot be read.
pub(crate) fn peak_rss() -> Option<u64> {
    kib_field("/proc/self/status", "VmHWM:")
}

/// Peak resident memory of this process so far, in MiB (Linux's `VmHWM`;
/// for tables and JSON lines); None where it cannot be read.
pub fn peak_rss_mib() -> Option<f64> {
    peak_rss().map(|b| b as f64 / (1024.0 * 1024.0))
}

/// Keep large freed buffers inside the process for the next allocation of
/// that size instead of returning them to the OS; call once at start-up.
///
/// glibc serves allocations above its mmap threshold (at most 32 MiB) with
/// fresh `mmap`s and unmaps them on free, so every training step that
/// allocates tens of MB of im2col, gradient and activation buffers paid for
/// zeroing and faulting in every page again: 31 % of a 1-thread SID U-Net
/// step was the kernel's page-fault path (BENCHMARKS.md, issue 15). With the
/// threshold raised to 1 GiB and heap trimming off, freed buffers are reused.
/// The cost: the process keeps its peak heap until it exits (peak RSS is
/// unchanged). Returns whether the allocator accepted both settings (false
/// off glibc, where this does nothing).
#[allow(unsafe_code)]
pub fn keep_freed_buffers() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: mallopt only changes two thresholds of glibc's allocator
        // (no pointers, no memory is touched); it is thread-safe.
        let mmap = unsafe { libc::mallopt(libc::M_MMAP_THRESHOLD, 1 << 30) };
        let trim = unsafe { libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX) };
        mmap == 1 && trim == 1
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        false
    }
}

#[cfg(test)]
mod tests {
    /// glibc accepts the thresholds (the 1 GiB mmap threshold is above the
    /// 32 MiB that older glibc versions allowed).
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    #[test]
    fn glibc_accepts_the_thresholds() {
        assert!(super::keep_freed_buffers());
    }

    #[test]
    fn peak_rss_grows_with_a_touched_allocation() {
        let before = super::peak_rss().expect("Linux /proc");
        // 64 MiB written page by page must raise the high-water mark.
        let v = vec![1u8; 64 << 20];
        std::hint::black_box(&v);
        let after = super::peak_rss().unwrap();
        assert!(after >= before.max(48 << 20), "{before} -> {after}");
        assert!(super::available_memory().unwrap() > 0);
    }
}
