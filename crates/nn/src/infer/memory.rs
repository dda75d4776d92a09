//! Choosing a tile size from the memory a machine has.
//!
//! The peak of a forward pass grows with the tile's pixel count times the
//! widest full-resolution layers' channels (activations, the skips the
//! U-Nets keep, the unfolded input of a 3x3 convolution). The per-pixel
//! costs below are measured, not derived: peak resident memory of
//! `pgrf enhance --json` on this project's 2-core CPU machine at two tile
//! sizes, the difference divided by the difference in pixels:
//! - SID U-Net, width 32: 305 MiB at 512^2, 804 MiB at 1024^2 -> ~670 B/px
//!   (5.2 floats per pixel per channel of width);
//! - SR3 default (inner 64): 772 MiB at 256^2, 1282 MiB at 512^2 ->
//!   ~2.7 KB/px (10.6 floats per pixel per inner channel).
//!
//! The estimates round these up by about a third.

use crate::weights::Architecture;

/// Estimated peak bytes per packed pixel of one tile's forward pass.
pub fn bytes_per_pixel(arch: &Architecture) -> f64 {
    let floats = match arch {
        Architecture::SidUnet(c) => 7.0 * c.width as f64,
        Architecture::Sr3(c) => {
            let w = c.inner_channels as f64 * c.channel_mults.first().copied().unwrap_or(1) as f64;
            14.0 * w + 16.0
        }
    };
    floats * 4.0
}

/// Memory the OS says is available for new allocations (Linux), in bytes.
pub fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    text.lines()
        .find(|l| l.starts_with("MemAvailable:"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|kb| kb.parse::<u64>().ok())
        .map(|kb| kb * 1024)
}

/// Peak resident memory of this process so far (Linux), in bytes.
pub fn peak_rss() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/self/status").ok()?;
    text.lines()
        .find(|l| l.starts_with("VmHWM:"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|kb| kb.parse::<u64>().ok())
        .map(|kb| kb * 1024)
}

/// The largest square tile, a multiple of `multiple` between `multiple` x 8
/// and 2048, whose estimated peak fits in `budget` bytes.
pub fn tile_for_budget(arch: &Architecture, multiple: usize, budget: u64) -> usize {
    let m = multiple.max(1);
    let per_px = bytes_per_pixel(arch);
    let side = (budget as f64 / per_px).sqrt() as usize;
    let lo = (8 * m).max(128);
    (side / m * m).clamp(lo, 2048.max(lo))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sr3::Sr3Config;
    use crate::unet::SidUnetConfig;

    #[test]
    fn tiles_grow_with_memory_and_stay_aligned() {
        let a = Architecture::SidUnet(SidUnetConfig::new());
        let small = tile_for_budget(&a, 16, 256 << 20);
        let big = tile_for_budget(&a, 16, 8 << 30);
        assert!(small < big, "{small} {big}");
        assert_eq!(small % 16, 0);
        assert_eq!(big % 16, 0);
        assert!(big <= 2048);
        assert_eq!(tile_for_budget(&a, 16, 1), 128);
        let f = Architecture::Sr3(Sr3Config::new());
        assert!(tile_for_budget(&f, 16, 1 << 30) < tile_for_budget(&a, 16, 1 << 30));
        assert!(available_memory().unwrap_or(1) > 0);
    }
}
