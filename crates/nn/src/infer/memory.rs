//! Choosing a tile size from the memory a machine has.
//!
//! The peak of a forward pass grows with the tile's pixel count times the
//! widest full-resolution layers' channels (activations, the skips the
//! U-Nets keep, the unfolded input of a 3x3 convolution). The per-pixel
//! costs are measured, not derived, and each network's file states its own
//! ([`crate::arch`]): peak resident memory of `pgrf enhance --json` on this
//! project's 2-core CPU machine at two tile sizes, the difference divided by
//! the difference in pixels, rounded up by about a third.

use crate::arch::Architecture;

/// Tokens of the largest self-attention in an `h` x `w` tile (zero for a
/// network without attention, such as the SID U-Net).
pub fn attention_tokens(arch: &Architecture, h: usize, w: usize) -> usize {
    arch.attention_tokens(h, w)
}

/// Estimated peak bytes of one `h` x `w` tile: the per-pixel activations
/// plus the attention scores and their softmax (tokens^2 floats each),
/// which grow with the square of the pixel count.
pub fn tile_bytes(arch: &Architecture, h: usize, w: usize) -> f64 {
    windowed_tile_bytes(arch, h, w, 0)
}

/// [`tile_bytes`] for a network that attends within `window` x `window`
/// windows ([`crate::Restore::window`]; 0: the whole tile): the scores are
/// then those of one window times the windows, linear in the pixels.
pub fn windowed_tile_bytes(arch: &Architecture, h: usize, w: usize, window: usize) -> f64 {
    let scores = if window == 0 || (h <= window && w <= window) {
        (attention_tokens(arch, h, w) as f64).powi(2)
    } else {
        let per = attention_tokens(arch, window, window) as f64;
        (h.div_ceil(window) * w.div_ceil(window)) as f64 * per * per
    };
    arch.bytes_per_pixel() * (h * w) as f64 + 2.0 * 4.0 * scores
}

/// The largest square tile, a multiple of `multiple` between
/// [`super::image::MIN_TILE`] (or 8 x `multiple`) and `cap`, whose estimated peak fits in `budget` bytes.
pub(crate) fn tile_for_budget(
    arch: &Architecture,
    multiple: usize,
    window: usize,
    budget: u64,
    cap: usize,
) -> usize {
    let m = multiple.max(1);
    let lo = (8 * m).max(super::image::MIN_TILE).div_ceil(m) * m;
    let by_pixels = (budget as f64 / arch.bytes_per_pixel()).sqrt() as usize;
    let mut side = (by_pixels.min(cap).max(lo) / m) * m;
    while side > lo && windowed_tile_bytes(arch, side, side, window) > budget as f64 {
        side -= m;
    }
    side.max(lo)
}

/// Largest tile `r` should see: memory alone bounds a network restoring
/// within windows ([`crate::Restore::window`]); otherwise the network's own
/// cap ([`Architecture::tile_cap`]), from the training patch its file
/// records (flow models: twice the patch, clamped to 512..2048, 512
/// unrecorded).
pub(crate) fn tile_cap(r: &dyn crate::infer::Restore) -> usize {
    if r.window() > 0 {
        return crate::arch::MEMORY_TILE_CAP;
    }
    let meta = r.meta();
    meta.arch.tile_cap(meta.training.as_ref().map(|t| t.patch))
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

/// Refuse to restore `file`'s `width` x `height` mosaic with `r` when the
/// memory there is cannot hold its frame buffers (one start field per flow
/// sample among them), the smallest tile the run would use, the restored
/// frame's DNG and, with `preview`, its sRGB preview; checked once the
/// frame is decoded, before any of these is allocated. `tile` is the
/// user's tile, else the automatic one; on CUDA the tiles are on the card
/// and only the host's buffers count.
pub fn check_frame(
    r: &dyn crate::infer::Restore,
    file: &std::path::Path,
    (width, height): (usize, usize),
    tile: Option<usize>,
    device: crate::backend::DeviceKind,
    preview: bool,
) -> Result<(), crate::NnError> {
    let (ph, pw) = (height / 2, width / 2);
    let pixels = (width * height) as f64;
    let mut need = fixed_bytes(r, ph, pw) as f64 + pixels * pgrf_raw::memory::WRITE;
    if preview {
        need += pixels * pgrf_raw::memory::PREVIEW_FULL;
    }
    if device == crate::backend::DeviceKind::Cpu {
        let t = tile
            .unwrap_or_else(|| auto_tile(device, r, ph, pw))
            .min(ph.max(pw));
        need += windowed_tile_bytes(&r.meta().arch, t.min(ph), t.min(pw), r.window());
    }
    let samples = r.samples();
    let what = format!(
        "{}: restoring its {width} x {height} frame ({:.0} MP){}",
        file.display(),
        pixels / 1e6,
        if samples > 1 {
            format!(" with --samples {samples}")
        } else {
            String::new()
        }
    );
    pgrf_core::mem::check_fits(&what, need).map_err(|e| {
        let hint = if samples > 1 {
            "; each sample holds a start field of the frame: give fewer --samples"
        } else {
            ""
        };
        crate::NnError::TooLarge(format!("{e}{hint}"))
    })
}

/// The largest tile side, in packed pixels, `pgrf enhance` picks on the
/// CPU by itself: a 24 MP frame (3000 x 2000 packed) with the built-in SPC
/// in 12 tiles of 800 took 6.2-6.3 s and 0.53 GiB peak against 6.9-7.8 s
/// and 2.49 GiB in one tile (2-core EPYC, 2 threads; BENCHMARKS.md): a
/// tile's activations that fit the caches beat one pass over the frame,
/// and memory follows the tile.
pub const CPU_TILE: usize = 1024;

/// The tile `pgrf enhance` uses unless told: on the CPU the largest tile
/// up to [`CPU_TILE`] whose estimated peak fits in half the available
/// memory once the frame's buffers and the weights are set aside (the
/// whole frame when it fits), on
/// CUDA (where burn does not report free memory) 1024, both within the
/// file's cap: 8192 for the denoiser and for flow models that restore within
/// windows of their training crop, else twice the crop clamped to
/// 512..2048 (512 when unrecorded). `ph` x `pw` is the packed
/// frame's size; returns a tile side in packed pixels.
pub fn auto_tile(
    device: crate::backend::DeviceKind,
    r: &dyn crate::infer::Restore,
    ph: usize,
    pw: usize,
) -> usize {
    let cap = tile_cap(r);
    let side = ph.max(pw);
    match device {
        crate::backend::DeviceKind::Cuda => 1024.min(cap),
        crate::backend::DeviceKind::Cpu => {
            let budget = (pgrf_core::mem::available_memory().unwrap_or(2 << 30) / 2)
                .saturating_sub(fixed_bytes(r, ph, pw));
            let arch = &r.meta().arch;
            let fits = windowed_tile_bytes(arch, ph, pw, r.window()) <= budget as f64;
            if side <= cap.min(CPU_TILE) && fits {
                side
            } else {
                tile_for_budget(
                    arch,
                    r.side_multiple(),
                    r.window(),
                    budget,
                    cap.min(CPU_TILE),
                )
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arch::{SidUnetConfig, Sr3Config};

    #[test]
    fn tiles_grow_with_memory_and_stay_aligned() {
        let a = Architecture::SidUnet(SidUnetConfig::new());
        let small = tile_for_budget(&a, 16, 0, 256 << 20, 2048);
        let big = tile_for_budget(&a, 16, 0, 8 << 30, 2048);
        assert!(small < big, "{small} {big}");
        assert_eq!(small % 16, 0);
        assert_eq!(big % 16, 0);
        assert!(big <= 2048);
        assert_eq!(tile_for_budget(&a, 16, 0, 1, 2048), 144);
        assert_eq!(tile_for_budget(&a, 16, 0, 8 << 30, 512), 512);
        let f = Architecture::Sr3(Sr3Config::new());
        assert!(
            tile_for_budget(&f, 16, 0, 1 << 30, 2048) < tile_for_budget(&a, 16, 0, 1 << 30, 2048)
        );
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
        // Within windows of 128 the scores are 64 windows of 16^2 tokens
        // each at a 1024 tile: 64 x 256^2 floats, not 16384^2.
        let per_pixel = f.bytes_per_pixel() * 1024.0 * 1024.0;
        let windowed = windowed_tile_bytes(&f, 1024, 1024, 128) - per_pixel;
        assert!(
            (windowed - 2.0 * 4.0 * 64.0 * 65536.0).abs() < 1.0,
            "{windowed}"
        );
        assert_eq!(
            windowed_tile_bytes(&f, 100, 60, 128),
            tile_bytes(&f, 100, 60)
        );
    }
}
