//! Choosing a tile size from the memory a machine has.
//!
//! The peak of a forward pass on the CPU backend is dominated by the widest
//! full-resolution layers: their activations, the skip connections the
//! U-Nets keep, and the unfolded (im2col) input of a 3x3 convolution, which
//! is nine times the input channels. The per-pixel costs below come from
//! that count and were checked against measured peaks (`pgrf enhance --json`
//! reports the process's peak memory); see BENCHMARKS.md.

use crate::weights::Architecture;

/// Estimated peak bytes per packed pixel of one tile's forward pass.
pub fn bytes_per_pixel(arch: &Architecture) -> f64 {
    let floats = match arch {
        Architecture::SidUnet(c) => {
            let w = c.width as f64;
            // Skips (~2w over all levels), the decoder's concatenated input
            // (2w) and its unfolded 3x3 form (18w), output and spare (~4w).
            26.0 * w
        }
        Architecture::Sr3(c) => {
            let w = c.inner_channels as f64 * c.channel_mults.first().copied().unwrap_or(1) as f64;
            let per_level_skips = (c.res_blocks + 1) as f64;
            // Skips kept at full resolution, a concatenated input (2w), its
            // unfold (18w), normalisation temporaries (3w); the sampler holds
            // the condition, X0 and the first estimate besides.
            w * (per_level_skips + 2.0 + 18.0 + 3.0) + 16.0
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
