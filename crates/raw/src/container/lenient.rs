//! The IFDs rawler reads without caring whether they are IFDs: the data
//! of an ICC profile, of an UNDEFINED or unknown-typed SubIFD entry, of a
//! Kodak IFD, of Panasonic's CameraIFD, and of Sony's encrypted SR2 block.
//! rawler parses each with `IFD::new` (formats/tiff/ifd.rs), which skips
//! entries it cannot read and stops at a truncated one, so garbage there is
//! harmless, except for one thing: `Entry::parse` allocates an entry's
//! values from the count it claims *before* reading them (32 GB for 2^32 - 1
//! doubles, an abort). This module follows rawler's own reading of those
//! structures (its types, its inline rule, its offset correction, one level
//! of sub-IFDs) and counts what they would allocate, where `tiff`'s strict
//! walk, which refuses any inconsistency, would refuse valid files whose ICC
//! profile merely is not an IFD.
//!
//! [`Values`] also bounds what all the entries rawler keeps add up to: 4,096
//! entries that each claim the whole file would make it hold 4,096 copies.

use super::order::Order;
use super::ContainerError;

/// rawler stops reading an IFD's entries after this many (formats/tiff/ifd.rs).
const RAWLER_MAX_ENTRIES: usize = 4096;

/// What rawler's reading of one file's entries may allocate: twice the file
/// or 512 MiB, whichever is more. A camera's entry values (MakerNotes,
/// previews, embedded originals) add up to less than the file; rawler
/// parses some structures twice.
pub(super) fn value_limit(file_len: usize) -> u64 {
    (512u64 << 20).max(2 * file_len as u64)
}

/// The bytes of entry values rawler would hold, and the largest single
/// allocation it would make, for one file.
#[derive(Clone, Copy, Debug)]
pub(super) struct Values {
    held: u64,
    limit: u64,
}

impl Values {
    pub(super) fn new(file_len: usize) -> Values {
        Values {
            held: 0,
            limit: value_limit(file_len),
        }
    }

    /// Charge one entry rawler reads: `bytes` allocated, and kept if its
    /// values lie inside the data (`kept`; otherwise the read fails and the
    /// allocation is dropped, so only its own size matters).
    pub(super) fn charge(
        &mut self,
        tag: u16,
        count: u64,
        bytes: u64,
        kept: bool,
    ) -> Result<(), ContainerError> {
        let mib = |b: u64| b as f64 / (1u64 << 20) as f64;
        if bytes > self.limit {
            return Err(ContainerError::malformed(format!(
                "malformed TIFF structure: tag {tag} claims {count} values ({:.0} MiB), more than the file could hold",
                mib(bytes)
            )));
        }
        if kept {
            self.held = self.held.saturating_add(bytes);
            if self.held > self.limit {
                return Err(ContainerError::malformed(format!(
                    "malformed TIFF structure: its entries' values add up to more than {:.0} MiB (tag {tag} among them)",
                    mib(self.limit)
                )));
            }
        }
        Ok(())
    }
}

/// Bytes rawler's `Entry::parse` allocates for `count` values of TIFF type
/// `kind`: rationals are read as pairs of u32 and then collected (16 bytes
/// each); every type it does not know, the IFD type 13 among them, is read
/// as bytes.
pub(super) fn alloc_bytes(kind: u16, count: u64) -> u64 {
    match kind {
        3 | 8 => 2 * count,
        4 | 9 | 11 => 4 * count,
        5 | 10 => 16 * count,
        12 => 8 * count,
        _ => count,
    }
}

/// Bytes of `count` values of `kind` as rawler sizes them to decide whether
/// they are inline (at most 4) or at an offset.
pub(super) fn data_bytes(kind: u16, count: u64) -> u64 {
    match kind {
        3 | 8 => 2 * count,
        4 | 9 | 11 => 4 * count,
        5 | 10 | 12 => 8 * count,
        _ => count,
    }
}

/// rawler's `apply_corr`: an offset moved by `corr` (wrapping to 32 bits).
fn corrected(offset: u32, corr: i64) -> u32 {
    (offset as i64 + corr) as u32
}

/// A structure rawler reads as TIFF: the bytes its reader sees, the byte
/// order, the base its offsets count from and the correction it adds to
/// every offset it reads.
#[derive(Clone, Copy)]
pub(super) struct Blob<'a> {
    pub(super) bytes: &'a [u8],
    pub(super) order: Order,
    pub(super) base: u64,
    pub(super) corr: i64,
}

/// One entry as rawler reads it.
#[derive(Debug)]
pub(super) struct RawlerEntry {
    pub(super) tag: u16,
    pub(super) kind: u16,
    pub(super) count: u64,
    /// Where the values are in the blob's bytes, and whether all of them
    /// lie inside it.
    pub(super) at: u64,
    pub(super) inside: bool,
    /// The value offset rawler records (`Entry::offset`).
    offset: u32,
}

impl RawlerEntry {
    /// The values' bytes, when inside.
    pub(super) fn data<'a>(&self, blob: &Blob<'a>) -> Option<&'a [u8]> {
        let len = data_bytes(self.kind, self.count);
        self.inside
            .then(|| &blob.bytes[self.at as usize..(self.at + len) as usize])
    }

    /// Value `i` as an unsigned integer, for the integer types rawler's
    /// `force_u32` converts.
    pub(super) fn uint(&self, blob: &Blob, i: u64) -> Option<u64> {
        let d = self.data(blob)?;
        let o = blob.order;
        match self.kind {
            1 | 7 => d.get(i as usize).map(|v| *v as u64),
            3 => o.u16(d, 2 * i as usize).map(u64::from),
            4 => o.u32(d, 4 * i as usize).map(u64::from),
            _ => None,
        }
    }
}

/// An IFD as rawler's `IFD::new` reads it.
#[derive(Debug)]
pub(super) struct RawlerIfd {
    pub(super) entries: Vec<RawlerEntry>,
    pub(super) next: u32,
}

impl RawlerIfd {
    /// The last entry with `tag` (rawler keeps one per tag, the last).
    pub(super) fn get(&self, tag: u16) -> Option<&RawlerEntry> {
        self.entries.iter().rev().find(|e| e.tag == tag)
    }
}

/// Read the IFD at `off` (already corrected) of `blob` as rawler's
/// `IFD::new` does, charging every entry's allocation to `values`, and
/// check the sub-IFDs its `sub_tags` name the same way (one level, as
/// rawler parses them with no sub-tags of their own). `None` where rawler
/// fails before reading any entry.
pub(super) fn check_ifd(
    blob: &Blob,
    off: u32,
    sub_tags: &[u16],
    values: &mut Values,
) -> Result<Option<RawlerIfd>, ContainerError> {
    let (b, o) = (blob.bytes, blob.order);
    let len = b.len() as u64;
    let start = blob.base + off as u64;
    let Some(n) = o.u16(b, start as usize).filter(|_| start + 2 <= len) else {
        return Ok(None);
    };
    let mut entries = Vec::new();
    let mut subs = Vec::new();
    let mut end = start + 2;
    for i in 0..(n as usize).min(RAWLER_MAX_ENTRIES) {
        let e = (start + 2 + 12 * i as u64) as usize;
        end = e as u64 + 12;
        // A truncated entry ends rawler's reading (the next one's seek or
        // tag read fails), and reads nothing it would allocate for.
        let (Some(tag), Some(kind), Some(count)) = (o.u16(b, e), o.u16(b, e + 2), o.u32(b, e + 4))
        else {
            break;
        };
        let count = count as u64;
        let size = data_bytes(kind, count);
        let offset = if size <= 4 {
            (e as u64 + 8 - blob.base) as u32
        } else {
            match o.u32(b, e + 8) {
                Some(v) => corrected(v, blob.corr),
                None => break,
            }
        };
        // rawler skips these tags ("invalid offset") before allocating.
        if offset == u32::MAX || blob.base + offset as u64 > u32::MAX as u64 {
            continue;
        }
        let at = blob.base + offset as u64;
        let inside = at + size <= len;
        values.charge(tag, count, alloc_bytes(kind, count), inside)?;
        let entry = RawlerEntry {
            tag,
            kind,
            count,
            at,
            inside,
            offset,
        };
        if sub_tags.contains(&tag) {
            subs.extend(sub_ifd_targets(blob, &entry));
        }
        entries.push(entry);
    }
    let next = o.u32(b, end as usize).unwrap_or(0);
    for t in subs {
        check_ifd(blob, corrected(t, blob.corr), &[], values)?;
    }
    let next = if next == 0 {
        0
    } else {
        corrected(next, blob.corr)
    };
    Ok(Some(RawlerIfd { entries, next }))
}

/// Where rawler's `IFD::new` looks for the sub-IFDs of a sub-IFD tag's
/// entry: every value of a LONG; the first *byte* of a type it does not
/// know (13, the IFD type, is one); the values' own offset for UNDEFINED
/// data (an ICC profile is parsed as an IFD this way); nothing for the
/// other types. Offsets before rawler applies the correction again.
pub(super) fn sub_ifd_targets(blob: &Blob, e: &RawlerEntry) -> Vec<u32> {
    match e.kind {
        4 => (0..e.count)
            .map_while(|i| e.uint(blob, i).map(|v| v as u32))
            .collect(),
        7 => vec![e.offset],
        k if k == 0 || k > 12 => e
            .data(blob)
            .and_then(|d| d.first())
            .map(|&v| vec![v as u32])
            .unwrap_or_default(),
        _ => Vec::new(),
    }
}

/// A TIFF structure at `blob.base` as rawler's `IFD::new_root_with_correction`
/// reads it: the header, the first IFD and at most `max_chain` more along
/// the next-IFD chain, each with `sub_tags`.
pub(super) fn check_root(
    blob: &Blob,
    max_chain: usize,
    sub_tags: &[u16],
    values: &mut Values,
) -> Result<(), ContainerError> {
    let (b, base) = (blob.bytes, blob.base as usize);
    let order = match b.get(base..base + 2) {
        Some(b"II") => Order(true),
        Some(b"MM") => Order(false),
        _ => return Ok(()),
    };
    let blob = Blob { order, ..*blob };
    if order.u16(b, base + 2) != Some(42) {
        return Ok(());
    }
    let mut next = match order.u32(b, base + 4) {
        Some(0) | None => return Ok(()),
        Some(v) => corrected(v, blob.corr),
    };
    let mut chained = 0;
    loop {
        let Some(ifd) = check_ifd(&blob, next, sub_tags, values)? else {
            return Ok(());
        };
        if ifd.entries.is_empty() || ifd.next == 0 || chained >= max_chain {
            return Ok(());
        }
        next = ifd.next;
        chained += 1;
    }
}

/// Sony's SR2 cipher, as rawler's `ArwDecoder::sony_decrypt` applies it:
/// a 127-word pad grown from `key` by a linear recurrence, each 32-bit
/// little-endian word of `data` XORed with the next pad word (byte-swapped,
/// as rawler leaves it on a little-endian machine). Applying it twice
/// gives the data back.
pub(super) fn sony_decrypt(data: &[u8], key: u32) -> Vec<u8> {
    let mut pad = [0u32; 128];
    let mut k = key;
    for p in pad.iter_mut().take(4) {
        k = k.wrapping_mul(48_828_125).wrapping_add(1);
        *p = k;
    }
    pad[3] = (pad[3] << 1) | ((pad[0] ^ pad[2]) >> 31);
    for p in 4..127 {
        pad[p] = ((pad[p - 4] ^ pad[p - 2]) << 1) | ((pad[p - 3] ^ pad[p - 1]) >> 31);
    }
    for p in pad.iter_mut().take(127) {
        *p = u32::from_be(*p);
    }
    let mut out = Vec::with_capacity(data.len());
    for (i, w) in data.chunks_exact(4).enumerate() {
        let p = i + 127;
        pad[p & 127] = pad[(p + 1) & 127] ^ pad[(p + 1 + 64) & 127];
        let v = u32::from_le_bytes(w.try_into().expect("4 bytes")) ^ pad[p & 127];
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// Tags rawler's decoders read from the file's root chain and parse as
/// IFDs of their own.
const TAG_PANASONIC_CAMERA_IFD: u16 = 0x0120;
const TAG_DNG_PRIVATE_AREA: u16 = 50740;
const TAG_SONY_OFFSET: u16 = 0x7200;
const TAG_SONY_LENGTH: u16 = 0x7201;
const TAG_SONY_KEY: u16 = 0x7221;

/// The IFDs rawler's decoders parse from data found through the root
/// chain (`chain`: the chain's IFD offsets, in order; rawler takes the
/// first IFD that has the tag):
///
/// - Panasonic's CameraIFD (decoders/rw2.rs, line 91): the entry's data is
///   a TIFF structure of its own, read with `IFD::new_root` (up to 10
///   chained IFDs, SubIFDs and EXIF one level);
/// - Sony's SR2 (decoders/arw.rs, lines 596-614): DNGPrivateArea's first
///   4 bytes (little-endian) are the offset of a little-endian IFD, whose
///   SonyOffset, SonyLength and SonyKey locate and unlock an encrypted IFD
///   that rawler decrypts and reads with its offsets moved by -SonyOffset.
pub(super) fn check_decoder_ifds(
    bytes: &[u8],
    order: Order,
    chain: &[u64],
    values: &mut Values,
) -> Result<(), ContainerError> {
    let file = Blob {
        bytes,
        order,
        base: 0,
        corr: 0,
    };
    let first = |tag: u16, values: &mut Values| -> Result<Option<RawlerEntry>, ContainerError> {
        for &ifd in chain {
            // Already charged by the strict walk: count them in a copy.
            let mut scratch = *values;
            if let Some(mut i) = check_ifd(&file, ifd as u32, &[], &mut scratch)? {
                if let Some(k) = i.entries.iter().rposition(|e| e.tag == tag) {
                    return Ok(Some(i.entries.swap_remove(k)));
                }
            }
        }
        Ok(None)
    };
    if let Some(cam) = first(TAG_PANASONIC_CAMERA_IFD, values)? {
        if let Some(d) = cam.data(&file) {
            let inner = Blob {
                bytes: d,
                order,
                base: 0,
                corr: 0,
            };
            check_root(&inner, 10, &[330, 34665], values)
                .map_err(|e| e.within(format!("in Panasonic's CameraIFD at byte {}", cam.at)))?;
        }
    }
    match first(TAG_DNG_PRIVATE_AREA, values)? {
        Some(private) => check_sony_sr2(&file, &private, values),
        None => Ok(()),
    }
}

/// Sony's SR2 block as rawler reads it (decoders/arw.rs, lines 596-614):
/// the little-endian IFD that DNGPrivateArea (`private`) points at, and
/// the encrypted IFD its SonyOffset, SonyLength and SonyKey locate,
/// decrypted and read with its offsets moved by -SonyOffset.
fn check_sony_sr2(
    file: &Blob,
    private: &RawlerEntry,
    values: &mut Values,
) -> Result<(), ContainerError> {
    let bytes = file.bytes;
    let Some(off) = private.data(file).and_then(|d| Order(true).u32(d, 0)) else {
        return Ok(());
    };
    let little = Blob {
        order: Order(true),
        ..*file
    };
    let Some(sr2) = check_ifd(&little, off, &[], values)? else {
        return Ok(());
    };
    let value = |tag| sr2.get(tag).and_then(|e| e.uint(&little, 0));
    let key = sr2
        .get(TAG_SONY_KEY)
        .and_then(|e| e.data(&little))
        .and_then(|d| Order(true).u32(d, 0));
    let (Some(s_off), Some(s_len), Some(key)) =
        (value(TAG_SONY_OFFSET), value(TAG_SONY_LENGTH), key)
    else {
        return Ok(());
    };
    let s_off = s_off as u32;
    let end = s_off as u64 + 4 * (s_len / 4);
    if end > bytes.len() as u64 {
        return Ok(()); // rawler: "buffer to short"
    }
    let plain = sony_decrypt(&bytes[s_off as usize..end as usize], key);
    let inner = Blob {
        bytes: &plain,
        order: Order(true),
        base: 0,
        corr: (s_off as i32).wrapping_neg() as i64,
    };
    check_ifd(&inner, 0, &[], values)
        .map(|_| ())
        .map_err(|e| e.within(format!("in Sony's encrypted SR2 block at byte {s_off}")))
}

#[cfg(test)]
mod tests {
    use super::super::testutil::le_ifd;
    use super::*;

    fn blob(b: &[u8]) -> Blob<'_> {
        Blob {
            bytes: b,
            order: Order(true),
            base: 0,
            corr: 0,
        }
    }

    #[test]
    fn rawler_sizes_and_allocations() {
        // The IFD type 13 is unknown to rawler: bytes, one per value.
        assert_eq!((data_bytes(13, 4), alloc_bytes(13, 4)), (4, 4));
        assert_eq!((data_bytes(5, 1), alloc_bytes(5, 1)), (8, 16));
        assert_eq!((data_bytes(12, 3), alloc_bytes(12, 3)), (24, 24));
        assert_eq!(alloc_bytes(12, u32::MAX as u64), 34_359_738_360);
    }

    #[test]
    fn a_garbage_ifd_passes_unless_it_would_allocate_too_much() {
        // Entries pointing outside, truncated, of odd types: rawler skips
        // them; nothing here claims much.
        let mut b = le_ifd(&[(1, 3, 100, 9999), (2, 77, 3, 0), (3, 4, 2, 6)], 123);
        b.truncate(b.len() - 6);
        let mut v = Values::new(b.len());
        let ifd = check_ifd(&blob(&b), 0, &[], &mut v).unwrap().unwrap();
        assert_eq!(ifd.entries.len(), 2);
        // One entry of 2^32 - 16 doubles: 32 GB asked of the allocator.
        let b = le_ifd(&[(1, 12, 0xFFFF_FFF0, 8)], 0);
        let e = check_ifd(&blob(&b), 0, &[], &mut Values::new(b.len()))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("tag 1 claims 4294967280 values (32768 MiB)"),
            "{e}"
        );
        // Values inside the data add up: 4,000 entries of 1 MiB each over a
        // 1 MiB blob is 4 GB held.
        let mut entries: Vec<(u16, u16, u32, u32)> =
            (0..4000).map(|t| (t, 1, 1 << 20, 0)).collect();
        entries.push((9, 1, 1, 0));
        let mut b = le_ifd(&entries, 0);
        b.resize(1 << 20, 0);
        let e = check_ifd(&blob(&b), 0, &[], &mut Values::new(b.len()))
            .unwrap_err()
            .to_string();
        assert!(e.contains("add up to more than 512 MiB"), "{e}");
    }

    #[test]
    fn sub_ifds_are_found_where_rawler_looks() {
        // A bad IFD at byte 100; each way rawler gets there from a sub tag.
        let bad = le_ifd(&[(1, 12, 0xFFFF_FFF0, 8)], 0);
        for (kind, count, value, what) in [
            (4u16, 1u32, 100u32, "LONG: the value"),
            (13, 1, 100, "IFD type, unknown to rawler: the first byte"),
            (7, 16, 100, "UNDEFINED: where the data is"),
        ] {
            let mut b = le_ifd(&[(34675, kind, count, value)], 0);
            b.resize(100, 0);
            b.extend_from_slice(&bad);
            let r = check_ifd(&blob(&b), 0, &[34675], &mut Values::new(b.len()));
            assert!(r.is_err(), "{what}");
            // Not a sub tag: not followed.
            assert!(check_ifd(&blob(&b), 0, &[330], &mut Values::new(b.len())).is_ok());
        }
        // A SHORT is no pointer to rawler.
        let mut b = le_ifd(&[(330, 3, 1, 100)], 0);
        b.resize(100, 0);
        b.extend_from_slice(&bad);
        assert!(check_ifd(&blob(&b), 0, &[330], &mut Values::new(b.len())).is_ok());
    }

    #[test]
    fn a_root_chain_stops_where_rawler_stops() {
        // A chain that loops (IFD at 8 -> 8) is read 11 times at most.
        let mut b = b"II*\0\x08\0\0\0".to_vec();
        b.extend_from_slice(&le_ifd(&[(1, 1, 1, 0)], 8));
        assert!(check_root(&blob(&b), 10, &[], &mut Values::new(b.len())).is_ok());
        // Big-endian, second IFD bad.
        let mut b = b"MM\0*\0\0\0\x08".to_vec();
        // One entry (tag 1, BYTE, count 1, value 0), then the next IFD at 26.
        b.extend_from_slice(&[0, 1, 0, 1, 0, 1, 0, 0, 0, 1, 0, 0, 0, 0]);
        b.extend_from_slice(&26u32.to_be_bytes());
        b.extend_from_slice(&1u16.to_be_bytes());
        b.extend_from_slice(&[0, 1, 0, 12, 0xFF, 0xFF, 0xFF, 0xF0, 0, 0, 0, 8, 0, 0, 0, 0]);
        let e = check_root(&blob(&b), 10, &[], &mut Values::new(b.len()))
            .unwrap_err()
            .to_string();
        assert!(e.contains("claims 4294967280 values"), "{e}");
    }

    /// The cipher's key stream against a Python implementation of the same
    /// recurrence (zeros in: the pad out), and its own inverse.
    #[test]
    fn the_sr2_cipher_matches_its_definition_and_is_its_own_inverse() {
        assert_eq!(
            sony_decrypt(&[0; 16], 1),
            [187, 37, 194, 245, 211, 144, 114, 173, 119, 210, 251, 125, 58, 223, 191, 103]
        );
        let long = sony_decrypt(&[0; 800], 0x1234_5678);
        assert_eq!(long[792..], [55, 175, 200, 143, 179, 13, 101, 203]);
        let data: Vec<u8> = (0..64u8).collect();
        let enc = sony_decrypt(&data, 0x1234_5678);
        assert_ne!(enc, data);
        assert_eq!(sony_decrypt(&enc, 0x1234_5678), data);
        assert_ne!(sony_decrypt(&enc, 0x1234_5679), data);
    }

    /// Sony's SR2 block: found through DNGPrivateArea and the private IFD,
    /// decrypted with the file's key, and read with its offsets moved by
    /// -SonyOffset, as rawler's ARW decoder does.
    #[test]
    fn the_encrypted_sr2_block_is_read_as_rawler_decrypts_it() {
        let key = 0x0BAD_F00D;
        let build = |plain: &[u8]| {
            let mut b = b"II*\0\x08\0\0\0".to_vec();
            b.extend_from_slice(&le_ifd(&[(TAG_DNG_PRIVATE_AREA, 1, 4, 32)], 0));
            b.resize(32, 0);
            let s_off = 32 + 2 + 3 * 12 + 4;
            b.extend_from_slice(&le_ifd(
                &[
                    (TAG_SONY_OFFSET, 4, 1, s_off),
                    (TAG_SONY_LENGTH, 4, 1, plain.len() as u32),
                    (TAG_SONY_KEY, 7, 4, key),
                ],
                0,
            ));
            assert_eq!(b.len(), s_off as usize);
            b.extend_from_slice(&sony_decrypt(plain, key));
            b
        };
        let check = |b: &[u8]| check_decoder_ifds(b, Order(true), &[8], &mut Values::new(b.len()));
        // A well-formed SR2 IFD whose 8 bytes of values sit right after it,
        // at an offset counted in the file (SonyOffset + 18): fine.
        let mut plain = le_ifd(&[(0x7303, 3, 4, 74 + 18)], 0);
        plain.extend_from_slice(&[1, 0, 2, 0, 3, 0, 4, 0]);
        assert_eq!(check(&build(&plain)), Ok(()));
        // One whose entry claims 2^32 - 16 doubles.
        let bad = le_ifd(&[(0x7303, 12, 0xFFFF_FFF0, 0)], 0);
        let e = check(&build(&bad)).unwrap_err().to_string();
        assert!(
            e.contains("claims 4294967280 values")
                && e.contains("Sony's encrypted SR2 block at byte 74"),
            "{e}"
        );
        // The correction puts the values where the writer meant them.
        let blob = Blob {
            bytes: &plain,
            order: Order(true),
            base: 0,
            corr: -74,
        };
        let ifd = check_ifd(&blob, 0, &[], &mut Values::new(plain.len()))
            .unwrap()
            .unwrap();
        assert_eq!(
            ifd.entries[0].data(&blob),
            Some(&[1, 0, 2, 0, 3, 0, 4, 0][..])
        );
    }
}
