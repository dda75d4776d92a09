//! A cheap look at a TIFF-based RAW container (DNG, ARW, NEF, CR2, KDC,
//! ...) before rawler decodes it, so that a malformed or hostile file is
//! refused with one line instead of costing the user their memory.
//!
//! rawler follows IFD chains without remembering where it has been (an IFD
//! whose next-IFD offset points back at itself makes it allocate without
//! limit) and trusts the dimensions a file claims. This walk reads only the
//! IFD entries, in bounded steps, and checks:
//!
//! - every IFD (the root chain, SubIFDs, EXIF, GPS and interoperability IFDs)
//!   lies inside the file and is visited once: a cycle is refused;
//! - at most [`MAX_IFDS`] IFDs and [`MAX_ENTRIES`] entries per IFD;
//! - every image's claimed width x height is at most [`MAX_PIXELS`], so a
//!   decode can never ask for more than a few GB;
//! - strip and tile extents lie inside the file and past the 8-byte header;
//! - in a DNG, an uncompressed image's strips hold the bits per sample it
//!   claims (BitsPerSample 8 over 14-bit data would decode to black).
//!
//! Files that are not TIFF (CR3, RAF's own header, ...) are not looked at
//! here; rawler's panics stay caught either way.

/// More pixels than any camera sensor (the largest pixel-shift modes give
/// ~400 MP); at 2 bytes per sample a decode of this many is 1.2 GB.
pub const MAX_PIXELS: u64 = 600_000_000;
/// More IFDs than any camera writes.
pub const MAX_IFDS: usize = 1024;
/// More entries than any IFD has.
pub const MAX_ENTRIES: usize = 4096;

const SUB_IFD_TAGS: [u16; 4] = [330, 34665, 34853, 40965];
const TAG_WIDTH: u16 = 256;
const TAG_LENGTH: u16 = 257;
const TAG_BITS: u16 = 258;
const TAG_COMPRESSION: u16 = 259;
const TAG_STRIP_OFFSETS: u16 = 273;
const TAG_SAMPLES: u16 = 277;
const TAG_STRIP_COUNTS: u16 = 279;
const TAG_TILE_WIDTH: u16 = 322;
const TAG_TILE_LENGTH: u16 = 323;
const TAG_TILE_OFFSETS: u16 = 324;
const TAG_TILE_COUNTS: u16 = 325;
const TAG_DNG_VERSION: u16 = 50706;

/// Byte order of the file.
#[derive(Clone, Copy)]
struct Order(bool);

impl Order {
    fn u16(self, b: &[u8], at: usize) -> Option<u16> {
        let s: [u8; 2] = b.get(at..at + 2)?.try_into().ok()?;
        Some(if self.0 {
            u16::from_le_bytes(s)
        } else {
            u16::from_be_bytes(s)
        })
    }
    fn u32(self, b: &[u8], at: usize) -> Option<u32> {
        let s: [u8; 4] = b.get(at..at + 4)?.try_into().ok()?;
        Some(if self.0 {
            u32::from_le_bytes(s)
        } else {
            u32::from_be_bytes(s)
        })
    }
}

/// One IFD entry's values: type, count and where they are.
struct Entry {
    kind: u16,
    count: u64,
    /// Offset of the values (inline ones: inside the entry).
    at: usize,
}

fn type_size(kind: u16) -> u64 {
    match kind {
        1 | 2 | 6 | 7 => 1,
        3 | 8 => 2,
        4 | 9 | 11 | 13 => 4,
        5 | 10 | 12 => 8,
        _ => 0,
    }
}

impl Entry {
    /// Value `i` as an unsigned integer (BYTE, SHORT, LONG or IFD types).
    fn value(&self, b: &[u8], o: Order, i: u64) -> Option<u64> {
        if i >= self.count {
            return None;
        }
        let at = self.at + (i * type_size(self.kind)) as usize;
        match self.kind {
            1 | 7 => b.get(at).map(|v| *v as u64),
            3 => o.u16(b, at).map(u64::from),
            4 | 13 => o.u32(b, at).map(u64::from),
            _ => None,
        }
    }

    fn values(&self, b: &[u8], o: Order) -> Vec<u64> {
        (0..self.count)
            .filter_map(|i| self.value(b, o, i))
            .collect()
    }
}

/// The image-describing entries of one IFD.
#[derive(Default)]
struct Image {
    width: Option<u64>,
    length: Option<u64>,
    bits: Option<u64>,
    samples: Option<u64>,
    compression: Option<u64>,
    strips: Vec<u64>,
    strip_counts: Vec<u64>,
    tiled: bool,
    tiles: Vec<u64>,
    tile_counts: Vec<u64>,
}

/// Check the container of `bytes` (see the module documentation); `Ok` for
/// files that are not TIFF. The message names the problem, for one line.
pub fn check(bytes: &[u8]) -> Result<(), String> {
    let order = match bytes.get(..2) {
        Some(b"II") => Order(true),
        Some(b"MM") => Order(false),
        _ => return Ok(()),
    };
    // Classic TIFF (42) and the TIFF-like RAWs with another magic (ORF's
    // 0x4f52/0x5352, RW2's 0x55) all keep the first IFD offset at byte 4.
    let Some(magic) = order.u16(bytes, 2) else {
        return Ok(());
    };
    if !matches!(magic, 42 | 0x4f52 | 0x5352 | 0x55) {
        return Ok(());
    }
    let first = order.u32(bytes, 4).ok_or("truncated TIFF header")? as u64;
    let mut walk = Walk {
        bytes,
        order,
        images: Vec::new(),
        dng: false,
        visits: 0,
        path: Vec::new(),
    };
    walk.ifd(first)?;
    for img in &walk.images {
        check_image(img, bytes.len() as u64, walk.dng)?;
    }
    Ok(())
}

/// A depth-first walk over the IFD graph: every IFD's sub-IFDs and its next
/// IFD are its children. An IFD on the current path reached again is a
/// loop (rawler would follow it forever); one shared by two paths is only
/// counted against [`MAX_IFDS`].
struct Walk<'a> {
    bytes: &'a [u8],
    order: Order,
    images: Vec<Image>,
    dng: bool,
    visits: usize,
    path: Vec<u64>,
}

/// Deeper than any camera's IFD nesting plus chain.
const MAX_DEPTH: usize = 64;

impl Walk<'_> {
    fn ifd(&mut self, off: u64) -> Result<(), String> {
        if off == 0 {
            return Ok(());
        }
        if self.path.contains(&off) {
            return Err(format!(
                "malformed TIFF structure: the IFD at byte {off} is reached twice (a loop in the IFD chain)"
            ));
        }
        self.visits += 1;
        if self.visits > MAX_IFDS || self.path.len() >= MAX_DEPTH {
            return Err(format!(
                "malformed TIFF structure: more than {MAX_IFDS} IFDs or {MAX_DEPTH} levels"
            ));
        }
        let (bytes, order) = (self.bytes, self.order);
        let len = bytes.len() as u64;
        let n = order
            .u16(bytes, off as usize)
            .filter(|_| off + 2 <= len)
            .ok_or_else(|| {
                format!("malformed TIFF structure: an IFD offset ({off}) lies beyond the file's {len} bytes")
            })? as usize;
        if n > MAX_ENTRIES {
            return Err(format!(
                "malformed TIFF structure: an IFD at byte {off} claims {n} entries"
            ));
        }
        let end = off + 2 + 12 * n as u64;
        if end + 4 > len {
            return Err(format!(
                "malformed TIFF structure: the IFD at byte {off} ({n} entries) runs past the end of the file"
            ));
        }
        let mut img = Image::default();
        let mut children = Vec::new();
        for k in 0..n {
            let e_at = off as usize + 2 + 12 * k;
            let tag = order.u16(bytes, e_at).expect("inside");
            let kind = order.u16(bytes, e_at + 2).expect("inside");
            let count = order.u32(bytes, e_at + 4).expect("inside") as u64;
            let size = type_size(kind).saturating_mul(count);
            let at = if size <= 4 {
                e_at + 8
            } else {
                let v = order.u32(bytes, e_at + 8).expect("inside") as u64;
                if v.saturating_add(size) > len {
                    return Err(format!(
                        "malformed TIFF structure: tag {tag}'s {count} values at byte {v} run past the end of the file"
                    ));
                }
                v as usize
            };
            let e = Entry { kind, count, at };
            let one = || e.value(bytes, order, 0);
            match tag {
                t if SUB_IFD_TAGS.contains(&t) => children.extend(e.values(bytes, order)),
                TAG_WIDTH => img.width = one(),
                TAG_LENGTH => img.length = one(),
                TAG_BITS => img.bits = one(),
                TAG_SAMPLES => img.samples = one(),
                TAG_COMPRESSION => img.compression = one(),
                TAG_STRIP_OFFSETS => img.strips = e.values(bytes, order),
                TAG_STRIP_COUNTS => img.strip_counts = e.values(bytes, order),
                TAG_TILE_WIDTH | TAG_TILE_LENGTH => img.tiled = true,
                TAG_TILE_OFFSETS => img.tiles = e.values(bytes, order),
                TAG_TILE_COUNTS => img.tile_counts = e.values(bytes, order),
                TAG_DNG_VERSION => self.dng = true,
                _ => {}
            }
        }
        children.push(order.u32(bytes, end as usize).expect("inside") as u64);
        self.images.push(img);
        self.path.push(off);
        for c in children {
            self.ifd(c)?;
        }
        self.path.pop();
        Ok(())
    }
}

fn check_image(img: &Image, len: u64, dng: bool) -> Result<(), String> {
    let (Some(w), Some(h)) = (img.width, img.length) else {
        return Ok(());
    };
    let pixels = w.saturating_mul(h);
    if pixels > MAX_PIXELS {
        return Err(format!(
            "the file claims a {w} x {h} image ({:.0} megapixels), more than any camera makes ({} MP): its header is damaged",
            pixels as f64 / 1e6,
            MAX_PIXELS / 1_000_000
        ));
    }
    for (what, offsets, counts) in [
        ("strip", &img.strips, &img.strip_counts),
        ("tile", &img.tiles, &img.tile_counts),
    ] {
        for (i, (&o, &c)) in offsets.iter().zip(counts.iter()).enumerate() {
            if c > 0 && o < 8 {
                return Err(format!(
                    "malformed TIFF structure: {what} {i} starts at byte {o}, inside the file header"
                ));
            }
            if o.saturating_add(c) > len {
                return Err(format!(
                    "the image data is truncated: {what} {i} ({c} bytes at byte {o}) runs past the file's {len} bytes"
                ));
            }
        }
    }
    // A DNG's uncompressed strips must hold the samples it claims.
    if dng && img.compression == Some(1) && !img.tiled && !img.strip_counts.is_empty() {
        let bits = img.bits.unwrap_or(1);
        let spp = img.samples.unwrap_or(1);
        let row = (w.saturating_mul(spp).saturating_mul(bits)).div_ceil(8);
        let need = row.saturating_mul(h);
        let have: u64 = img
            .strip_counts
            .iter()
            .fold(0u64, |a, &c| a.saturating_add(c));
        if have < need || have > need.saturating_add(need / 4).saturating_add(64) {
            let held = have as f64 * 8.0 / (w as f64 * h as f64 * spp as f64).max(1.0);
            return Err(format!(
                "inconsistent DNG: BitsPerSample says {bits} for a {w} x {h} image, but its uncompressed strips hold {held:.1} bits per sample"
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A little-endian TIFF: header, one IFD at byte 8 with `entries`
    /// (tag, type, count, value), next-IFD offset `next`, then `tail`.
    fn tiff(entries: &[(u16, u16, u32, u32)], next: u32, tail: &[u8]) -> Vec<u8> {
        let mut b = b"II*\0\x08\0\0\0".to_vec();
        b.extend_from_slice(&(entries.len() as u16).to_le_bytes());
        for &(t, k, c, v) in entries {
            b.extend_from_slice(&t.to_le_bytes());
            b.extend_from_slice(&k.to_le_bytes());
            b.extend_from_slice(&c.to_le_bytes());
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&next.to_le_bytes());
        b.extend_from_slice(tail);
        b
    }

    /// 64 x 32 image, `bits` per sample, one strip of `strip_bytes` right
    /// after the IFD (4096 bytes hold it at 16 bits).
    fn image(bits: u32, strip_bytes: u32, dng: bool) -> Vec<u8> {
        let n = if dng { 9 } else { 8 };
        let data_at = 8 + 2 + 12 * n + 4;
        let mut e = vec![
            (256, 3, 1, 64),
            (257, 3, 1, 32),
            (258, 3, 1, bits),
            (259, 3, 1, 1),
            (273, 4, 1, data_at),
            (277, 3, 1, 1),
            (279, 4, 1, strip_bytes),
            (254, 4, 1, 0),
        ];
        if dng {
            e.push((50706, 1, 4, 0x0004_0101));
        }
        tiff(&e, 0, &vec![0u8; strip_bytes as usize])
    }

    #[test]
    fn well_formed_files_and_non_tiffs_pass() {
        assert_eq!(check(&image(16, 4096, true)), Ok(()));
        assert_eq!(check(&image(16, 4096, false)), Ok(()));
        assert_eq!(check(b"not a tiff at all"), Ok(()));
        assert_eq!(check(b""), Ok(()));
    }

    #[test]
    fn loops_and_offsets_outside_the_file_are_refused() {
        // The first IFD's next-IFD offset is its own.
        let e = check(&tiff(&[(256, 3, 1, 4)], 8, &[])).unwrap_err();
        assert!(e.contains("reached twice"), "{e}");
        // A SubIFD pointing back at the root.
        let e = check(&tiff(&[(330, 4, 1, 8)], 0, &[])).unwrap_err();
        assert!(e.contains("reached twice"), "{e}");
        let e = check(&tiff(&[(256, 3, 1, 4)], 1 << 30, &[])).unwrap_err();
        assert!(e.contains("beyond the file"), "{e}");
        // Values (10 LONGs) said to lie past the end.
        let e = check(&tiff(&[(273, 4, 10, 4000)], 0, &[])).unwrap_err();
        assert!(e.contains("past the end"), "{e}");
        // An IFD claiming more entries than the file holds.
        let mut b = tiff(&[(256, 3, 1, 4)], 0, &[]);
        b[8] = 200;
        assert!(check(&b).unwrap_err().contains("runs past the end"));
    }

    #[test]
    fn impossible_sizes_and_inconsistent_data_are_refused() {
        let mut huge = image(16, 4096, true);
        // ImageLength 0xFFFFFFFF as a LONG.
        huge[8 + 2 + 12 + 2..8 + 2 + 12 + 4].copy_from_slice(&4u16.to_le_bytes());
        huge[8 + 2 + 12 + 8..8 + 2 + 12 + 12].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(check(&huge).unwrap_err().contains("megapixels"));
        // BitsPerSample 8 over 16-bit data, and 16 over too little data.
        let e = check(&image(8, 4096, true)).unwrap_err();
        assert!(
            e.contains("BitsPerSample says 8") && e.contains("16.0 bits"),
            "{e}"
        );
        let mut short = image(16, 4096, true);
        let at = 8 + 2 + 12 * 6 + 8;
        short[at..at + 4].copy_from_slice(&8u32.to_le_bytes());
        assert!(check(&short).unwrap_err().contains("BitsPerSample says 16"));
        // Outside a DNG the bits are not checked (unpacked 12-bit NEFs).
        assert_eq!(check(&image(12, 4096, false)), Ok(()));
        // A strip at offset 0 reads the header as pixels; one past the end.
        let mut zero = image(16, 4096, true);
        let at = 8 + 2 + 12 * 4 + 8;
        zero[at..at + 4].copy_from_slice(&0u32.to_le_bytes());
        assert!(check(&zero).unwrap_err().contains("inside the file header"));
        let mut past = image(16, 4096, false);
        past.truncate(past.len() - 4);
        assert!(check(&past).unwrap_err().contains("truncated"));
    }
}
