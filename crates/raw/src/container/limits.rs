//! The bounds every container walk enforces: no camera writes more IFDs,
//! entries, listed offsets, boxes or pixels than these, so a file that
//! claims more is refused before rawler allocates for it.

/// More pixels than any camera sensor (the largest pixel-shift modes give
/// ~400 MP); at 2 bytes per sample a decode of this many is 1.2 GB.
pub const MAX_PIXELS: u64 = 600_000_000;
/// More IFDs than any camera writes.
pub const MAX_IFDS: usize = 1024;
/// More entries than any IFD has.
pub const MAX_ENTRIES: usize = 4096;
/// More strip and tile offsets and counts (and sub-IFD offsets), summed
/// over the file, than any camera writes (a 400 MP image in 256 x 256 tiles
/// has 6,100 tiles).
pub const MAX_LISTED: u64 = 1 << 22;
/// More boxes than a CR3 (about 70 of them) or a Canon RAW movie has.
pub const MAX_BOXES: usize = 1 << 16;

/// The megapixels of a `w` x `h` image, when more than [`MAX_PIXELS`].
pub(crate) fn too_many_pixels(w: u64, h: u64) -> Option<String> {
    let pixels = w.saturating_mul(h);
    (pixels > MAX_PIXELS).then(|| {
        format!(
            "a {w} x {h} image ({:.0} megapixels), more than any camera makes ({} MP)",
            pixels as f64 / 1e6,
            MAX_PIXELS / 1_000_000
        )
    })
}
