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
pub(crate) fn bytes_per_pixel(arch: &Architecture) -> f64 {
    let floats = match arch {
        Architecture::SidUnet(c) => 7.0 * c.width as f64,
        Architecture::Sr3(c) => {
            let w = c.inner_channels as f64 * c.channel_mults.first().copied().unwrap_or(1) as f64;
            14.0 * w + 16.0
        }
    };
    floats * 4.0
}

/// Tokens of the largest self-attention in an `h` x `w` tile: SR3 attends
/// at its `attn_levels` and in the first middle block (the last level); each
/// level halves the side, rounding up. Zero for the SID U-Net.
pub fn attention_tokens(arch: &Architecture, h: usize, w: usize) -> usize {
    let Architecture::Sr3(c) = arch else {
        return 0;
    };
    let last = c.channel_mults.len().saturating_sub(1);
    c.attn_levels
        .iter()
        .copied()
        .chain(std::iter::once(last))
        .filter(|&l| l <= last)
        .map(|l| h.div_ceil(1 << l) * w.div_ceil(1 << l))
        .max()
        .unwrap_or(0)
}

/// Estimated peak bytes of one `h` x `w` tile: the per-pixel activations
/// plus the attention scores and their softmax (tokens^2 floats each),
/// which grow with the square of the pixel count.
pub fn tile_bytes(arch: &Architecture, h: usize, w: usize) -> f64 {
    let tokens = attention_tokens(arch, h, w) as f64;
    bytes_per_pixel(arch) * (h * w) as f64 + 2.0 * 4.0 * tokens * tokens
}

/// The largest square tile, a multiple of `multiple` between
/// [`super::image::MIN_TILE`] (or 8 x `multiple`) and `cap`, whose estimated peak fits in `budget` bytes.
pub(crate) fn tile_for_budget(
    arch: &Architecture,
    multiple: usize,
    budget: u64,
    cap: usize,
) -> usize {
    let m = multiple.max(1);
    let lo = (8 * m).max(super::image::MIN_TILE).div_ceil(m) * m;
    let by_pixels = (budget as f64 / bytes_per_pixel(arch)).sqrt() as usize;
    let mut side = (by_pixels.min(cap).max(lo) / m) * m;
    while side > lo && tile_bytes(arch, side, side) > budget as f64 {
        side -= m;
    }
    side.max(lo)
}

/// Largest tile a file's network should see. Self-attention relates every
/// position of a tile to every other, and its memory grows with the square
/// of the tokens, so flow models are held to twice the training patch, but
/// never below 512 (512 when the file does not record it). The floor is
/// measured: the shipped flow model, trained on 64-pixel crops, scores
/// 29.45 dB on the demo's x100 capture in tiles of 128 (overlap 32), 29.92
/// in tiles of 256 and 30.03 as one 768 x 512 tile: small tiles cost more
/// at their borders than a softmax over more tokens than in training does.
/// The convolutional denoiser is limited by memory alone.
pub(crate) fn tile_cap(meta: &crate::weights::WeightMeta) -> usize {
    match meta.arch {
        Architecture::SidUnet(_) => 8192,
        Architecture::Sr3(_) => meta
            .training
            .as_ref()
            .map_or(512, |t| (2 * t.patch).clamp(512, 2048)),
    }
}

/// Estimated peak bytes of a training step on `batch` crops of `patch` x
/// `patch`: the forward activations of every crop kept for the backward
/// pass, their gradients and the kernels' scratch, about three times a
/// forward pass's peak.
pub fn training_bytes(arch: &Architecture, patch: usize, batch: usize) -> f64 {
    3.0 * batch as f64 * tile_bytes(arch, patch, patch)
}

/// Bytes held for the whole run besides the tiles: the frame's input,
/// output and blend buffers, one start field per flow sample, and the
/// network's weights.
pub fn fixed_bytes(r: &dyn crate::infer::Restore, ph: usize, pw: usize) -> u64 {
    (4 * ph * pw * 4 * (3 + r.samples())) as u64 + r.weight_bytes()
}

/// The tile `pgrf enhance` uses unless told: on the CPU the largest tile
/// whose estimated peak fits in half the available memory once the frame's
/// buffers and the weights are set aside (the whole frame when it fits), on
/// CUDA (where burn does not report free memory) 1024, both within the
/// file's cap: twice the training patch clamped to 512..2048 for flow models
/// (512 when unrecorded), 8192 for the denoiser. `ph` x `pw` is the packed
/// frame's size; returns a tile side in packed pixels.
pub fn auto_tile(
    device: crate::backend::DeviceKind,
    r: &dyn crate::infer::Restore,
    ph: usize,
    pw: usize,
) -> usize {
    let cap = tile_cap(r.meta());
    let side = ph.max(pw);
    match device {
        crate::backend::DeviceKind::Cuda => 1024.min(cap),
        crate::backend::DeviceKind::Cpu => {
            let budget = (pgrf_core::mem::available_memory().unwrap_or(2 << 30) / 2)
                .saturating_sub(fixed_bytes(r, ph, pw));
            let arch = &r.meta().arch;
            if side <= cap && tile_bytes(arch, ph, pw) <= budget as f64 {
                side
            } else {
                tile_for_budget(arch, r.side_multiple(), budget, cap)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sr3::Sr3Config;
    use crate::unet::SidUnetConfig;

    #[test]
    fn tiles_grow_with_memory_and_stay_aligned() {
        let a = Architecture::SidUnet(SidUnetConfig::new());
        let small = tile_for_budget(&a, 16, 256 << 20, 2048);
        let big = tile_for_budget(&a, 16, 8 << 30, 2048);
        assert!(small < big, "{small} {big}");
        assert_eq!(small % 16, 0);
        assert_eq!(big % 16, 0);
        assert!(big <= 2048);
        assert_eq!(tile_for_budget(&a, 16, 1, 2048), 144);
        assert_eq!(tile_for_budget(&a, 16, 8 << 30, 512), 512);
        let f = Architecture::Sr3(Sr3Config::new());
        assert!(tile_for_budget(&f, 16, 1 << 30, 2048) < tile_for_budget(&a, 16, 1 << 30, 2048));
        assert!(pgrf_core::mem::available_memory().unwrap_or(1) > 0);
    }

    #[test]
    fn attention_dominates_large_flow_tiles() {
        // Default SR3 attends at level 3 and in the middle (level 4): at a
        // 1024 tile, level 3 has 128^2 = 16384 tokens, scores 16384^2 floats.
        let f = Architecture::Sr3(Sr3Config::new());
        assert_eq!(attention_tokens(&f, 1024, 1024), 128 * 128);
        assert_eq!(attention_tokens(&f, 100, 60), 13 * 8);
        assert_eq!(attention_tokens(&f, 1424, 2128), 178 * 266);
        let mid_only = Architecture::Sr3(Sr3Config::new().with_attn_levels(vec![]));
        assert_eq!(attention_tokens(&mid_only, 512, 512), 32 * 32);
        let scores = 2.0 * 4.0 * (16384.0f64).powi(2);
        assert!(tile_bytes(&f, 1024, 1024) > scores);
        let a = Architecture::SidUnet(SidUnetConfig::new());
        assert_eq!(attention_tokens(&a, 1024, 1024), 0);
    }
}
