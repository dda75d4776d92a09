//! Memory per mosaic pixel of the stages a frame goes through, so that a
//! frame too large for the machine is refused in one line with the figures
//! (`pgrf_core::mem::check_fits`) before the allocation that would abort
//! the process. The figures are peak resident bytes per pixel measured with
//! `/usr/bin/time -f %M` on a 48 MP (8000 x 6000) 16-bit Bayer FITS on the
//! 2-core VM, rounded up: `pgrf info` 296 MB (6.2 B/px with the file's
//! 2 B/px), `preview --half` 572 MB (12 B/px), `preview` 1,416 MB
//! (30 B/px), `convert` 197 MB (4.1 B/px).

use crate::{RawError, Result};
use std::path::Path;

/// Decoding: the decoder's samples and the frame's own copy (the file
/// itself is already mapped or read when this is checked).
pub const DECODE: f64 = 6.0;
/// A half-size sRGB preview, beyond the decoded frame.
pub const PREVIEW_HALF: f64 = 8.0;
/// A full-size (demosaiced) sRGB preview, beyond the decoded frame.
pub const PREVIEW_FULL: f64 = 26.0;
/// Writing a DNG (or FITS) of the frame, beyond the frame.
pub const WRITE: f64 = 4.0;

/// Refuse `stage` of `file`'s `width` x `height` frame when `bytes_per_pixel`
/// of it cannot be had: one line naming the file, the frame, the stage and
/// both figures.
pub fn check_frame(
    file: &Path,
    stage: &str,
    width: usize,
    height: usize,
    bytes_per_pixel: f64,
) -> Result<()> {
    let need = width as f64 * height as f64 * bytes_per_pixel;
    let what = format!(
        "{stage} its {width} x {height} frame ({:.0} MP)",
        width as f64 * height as f64 / 1e6
    );
    pgrf_core::mem::check_fits(&what, need).map_err(|e| RawError::Memory {
        path: file.to_path_buf(),
        reason: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_frame_beyond_any_memory_is_refused_with_the_figures() {
        // 65536 x 65536 at 1 MB/px is 4 million GiB: more than any machine
        // has.
        let e = super::check_frame(
            std::path::Path::new("big.fits"),
            "previewing",
            65536,
            65536,
            1e6,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.starts_with("big.fits: previewing its 65536 x 65536 frame (4295 MP) needs about 4000000.0 GiB of memory, "),
            "{e}"
        );
        super::check_frame(
            std::path::Path::new("small"),
            "decoding",
            64,
            48,
            super::DECODE,
        )
        .unwrap();
    }
}
