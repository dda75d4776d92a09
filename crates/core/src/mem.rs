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

/// Memory the OS says is available for new allocations, in bytes (Linux's
/// `MemAvailable`); None where it cannot be read.
pub fn available_memory() -> Option<u64> {
    kib_field("/proc/meminfo", "MemAvailable:")
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

#[cfg(test)]
mod tests {
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
