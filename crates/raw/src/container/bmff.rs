//! ISO BMFF boxes, as rawler parses every file it does not recognise by
//! its magic, and what a CR3's boxes point at: Canon's CMT TIFF structures,
//! the CMP1 image dimensions and the CTMD timed metadata. The boxes are a
//! format of their own (sizes, nesting, tables), so they are walked here;
//! the TIFF structures they hold are walked by `tiff`.

use super::limits::{too_many_pixels, MAX_BOXES};
use super::makernote::Notes;
use super::order::Order;
use super::tiff::{check_tiff, SUB_IFD_TAGS};
use super::ContainerError;

/// More CMT boxes than a CR3 has (4): rawler parses the TIFF structure of
/// each it meets, and so does this walk.
const MAX_CMT_BOXES: usize = 64;

/// The UUID of the box in `moov` that holds Canon's CMT1..CMT4 TIFF
/// structures (rawler's `Cr3DescBox`, formats/bmff/ext_cr3/cr3desc.rs).
const CR3_DESC_UUID: [u8; 16] = [
    0x85, 0xc0, 0xb6, 0x87, 0x82, 0x0f, 0x11, 0xe0, 0x81, 0x11, 0xf4, 0xce, 0x46, 0x2b, 0x6a, 0x48,
];

/// The boxes whose children rawler's BMFF parser reads (formats/bmff/*.rs,
/// ext_cr3/*.rs), each only where it sits in this hierarchy (a `trak`
/// inside `trak` is read as an opaque box), so nesting is at most 9 deep.
#[derive(Clone, Copy, PartialEq)]
enum BoxKind {
    Moov,
    Trak,
    Mdia,
    Minf,
    Stbl,
    Stsd,
    Craw,
    Cdi1,
    Cctp,
    Cr3Desc,
}

impl BoxKind {
    /// Bytes of fields before the first child: stsd.rs reads version, flags
    /// and an entry count, craw.rs an 82-byte sample entry, cdi1.rs version
    /// and flags, cctp.rs 12 bytes.
    fn fields(self) -> u64 {
        match self {
            BoxKind::Stsd => 8,
            BoxKind::Craw => 82,
            BoxKind::Cdi1 => 4,
            BoxKind::Cctp => 12,
            _ => 0,
        }
    }

    /// The kind of `child`, a box inside this one, if rawler reads its
    /// children.
    fn child(self, child: &BoxHead) -> Option<BoxKind> {
        Some(match (self, &child.typ) {
            (BoxKind::Moov, b"trak") => BoxKind::Trak,
            (BoxKind::Moov, b"uuid") if child.uuid == Some(CR3_DESC_UUID) => BoxKind::Cr3Desc,
            (BoxKind::Trak, b"mdia") => BoxKind::Mdia,
            (BoxKind::Mdia, b"minf") => BoxKind::Minf,
            (BoxKind::Minf, b"stbl") => BoxKind::Stbl,
            (BoxKind::Stbl, b"stsd") => BoxKind::Stsd,
            (BoxKind::Stsd, b"CRAW") => BoxKind::Craw,
            (BoxKind::Craw, b"CDI1") => BoxKind::Cdi1,
            (BoxKind::Cr3Desc, b"CCTP") => BoxKind::Cctp,
            _ => return None,
        })
    }
}

/// A box header, as rawler's `BoxHeader::parse` (formats/bmff/mod.rs)
/// reads it: 4-byte big-endian size (1: a 64-bit size follows), 4-byte
/// type, and for "uuid" a 16-byte UUID.
struct BoxHead {
    at: u64,
    size: u64,
    typ: [u8; 4],
    uuid: Option<[u8; 16]>,
    /// Bytes of the header.
    len: u64,
}

impl BoxHead {
    /// The header at `at`; `None` where it runs past the end of `b`.
    fn read(b: &[u8], at: u64) -> Option<BoxHead> {
        let a = usize::try_from(at).ok()?;
        let be = Order(false);
        let mut size = be.u32(b, a)? as u64;
        let typ: [u8; 4] = b.get(a + 4..a + 8)?.try_into().ok()?;
        let mut len = 8;
        if size == 1 {
            size = (be.u32(b, a + 8)? as u64) << 32 | be.u32(b, a + 12)? as u64;
            len = 16;
        }
        let mut uuid = None;
        if &typ == b"uuid" {
            uuid = Some(b.get(a + len..a + len + 16)?.try_into().ok()?);
            len += 16;
        }
        Some(BoxHead {
            at,
            size,
            typ,
            uuid,
            len: len as u64,
        })
    }

    fn name(&self) -> String {
        self.typ.escape_ascii().to_string()
    }
}

/// Where the entries of a trak's sample tables are, for rawler's
/// `StblBox::get_sample_offset` (formats/bmff/stbl.rs); a later box of a
/// kind replaces an earlier one, as in rawler.
#[derive(Default)]
struct Trak {
    /// Its sample description has a CTMD box: the CR3 decoder reads its
    /// first sample as Canon's timed metadata.
    ctmd: bool,
    /// stsc: where the entries are, how many.
    stsc: Option<(usize, u32)>,
    /// stsz: the one sample size (0: each has its own), the sample count,
    /// where the sizes are.
    stsz: Option<(u32, u32, usize)>,
    /// co64: where the chunk offsets are, how many.
    co64: Option<(usize, u32)>,
}

/// rawler parses any file it has not recognised by its magic as ISO BMFF
/// boxes (`FileBox::parse`, formats/bmff/mod.rs, line 139) before it tries
/// TIFF, and for a CR3 its decoder then reads what the boxes point at.
/// rawler
///
/// - loops without end, keeping a record of every box it reads, on a box
///   inside a container (moov, trak, ...) that does not move it forward
///   (size 0, or smaller than its header: moov.rs, trak.rs, ... have no
///   check), and at the top level on a size that wraps the box's end offset
///   around 2^64 (mod.rs, `end_offset`);
/// - allocates the size of a CMT1..CMT4 or CNOP box (cmt1.rs, line 25), and
///   the entry counts of stts, stsc, stsz, co64 and CTMD boxes (stts.rs,
///   line 33, ...), before it reads them;
/// - parses CMT1..CMT4 as TIFF, and in the CTMD sample records whose sizes
///   it allocates before reading them (decoders/cr3.rs, `Ctmd::new`) and
///   TIFF structures in records 7 to 9;
/// - allocates the width x height of the CMP1 box (decoders/cr3.rs, line
///   316).
///
/// So every box inside a container lies inside it and the file, at most
/// [`MAX_BOXES`] boxes are read, each count fits in its box (stsz's with one
/// size for all samples: in the file), CMP1's dimensions are at most
/// [`MAX_PIXELS`], the CTMD records fit in their sample, and the TIFF
/// structures are walked. A file that starts with an `ftyp` box, as every
/// CR3 does, also has its top-level boxes checked like that; any other file
/// (a TIFF, whose first bytes read as a box of about 1.2 GB) is refused
/// only for what would make rawler loop or allocate.
///
/// [`MAX_PIXELS`]: super::MAX_PIXELS
pub(super) fn check_bmff(bytes: &[u8]) -> Result<(), ContainerError> {
    let len = bytes.len() as u64;
    let bmff = bytes.get(4..8) == Some(&b"ftyp"[..]);
    let mut walk = Boxes {
        bytes,
        count: 0,
        cmt: 0,
        traks: Vec::new(),
    };
    let mut at = 0;
    while at < len {
        let Some(h) = BoxHead::read(bytes, at) else {
            if bmff {
                return Err(ContainerError::malformed(format!(
                    "malformed BMFF structure: the box header at byte {at} runs past the end of the file's {len} bytes"
                )));
            }
            break;
        };
        walk.count()?;
        // Size 0 is "to the end of the file" in ISO BMFF; rawler stops at
        // it with an error.
        if h.size == 0 {
            break;
        }
        let Some(end) = at.checked_add(h.size) else {
            return Err(ContainerError::malformed(format!(
                "malformed BMFF structure: the {} box at byte {at} claims {} bytes, beyond any file (rawler would wrap around to an earlier box and loop)",
                h.name(),
                h.size
            )));
        };
        if bmff {
            walk.inside(&h, None)?;
        }
        if &h.typ == b"moov" {
            // rawler keeps the last moov
            walk.traks.clear();
            walk.children(BoxKind::Moov, &h)?;
        }
        at = end;
    }
    // The CR3 decoder reads the first trak with a CTMD box.
    match walk.traks.iter().find(|t| t.ctmd) {
        Some(trak) => walk.check_ctmd(trak),
        None => Ok(()),
    }
}

/// A walk over the boxes of a file.
struct Boxes<'a> {
    bytes: &'a [u8],
    count: usize,
    /// CMT boxes walked.
    cmt: usize,
    traks: Vec<Trak>,
}

impl Boxes<'_> {
    fn count(&mut self) -> Result<(), ContainerError> {
        self.count += 1;
        if self.count > MAX_BOXES {
            return Err(ContainerError::malformed(format!(
                "malformed BMFF structure: more than {MAX_BOXES} boxes"
            )));
        }
        Ok(())
    }

    /// `h` is no smaller than its header and lies inside `parent` (if any)
    /// and the file.
    fn inside(&self, h: &BoxHead, parent: Option<&BoxHead>) -> Result<(), ContainerError> {
        let len = self.bytes.len() as u64;
        let name = h.name();
        if h.size < h.len {
            return Err(ContainerError::malformed(format!(
                "malformed BMFF structure: the {name} box at byte {} claims {} bytes, less than its {}-byte header",
                h.at, h.size, h.len
            )));
        }
        let end = h.at.saturating_add(h.size);
        if let Some(p) = parent.filter(|p| end > p.at.saturating_add(p.size)) {
            return Err(ContainerError::malformed(format!(
                "malformed BMFF structure: the {name} box at byte {} ({} bytes) runs past the end of the {} box at byte {}",
                h.at,
                h.size,
                p.name(),
                p.at
            )));
        }
        if end > len {
            return Err(ContainerError::malformed(format!(
                "malformed BMFF structure: the {name} box at byte {} ({} bytes) runs past the end of the file's {len} bytes",
                h.at, h.size
            )));
        }
        Ok(())
    }

    /// Walk the children of `parent`, a box of kind `kind`, the way rawler
    /// reads them.
    fn children(&mut self, kind: BoxKind, parent: &BoxHead) -> Result<(), ContainerError> {
        let len = self.bytes.len() as u64;
        let end = parent.at.saturating_add(parent.size);
        let mut at = parent.at + parent.len + kind.fields();
        while at < end {
            let head = BoxHead::read(self.bytes, at);
            let Some(h) = head.as_ref().filter(|h| at + h.len <= end) else {
                let what = match head {
                    None => format!("the file's {len} bytes"),
                    Some(_) => format!("the {} box at byte {}", parent.name(), parent.at),
                };
                return Err(ContainerError::malformed(format!(
                    "malformed BMFF structure: the box header at byte {at} runs past the end of {what}"
                )));
            };
            self.count()?;
            self.inside(h, Some(parent))?;
            match kind.child(h) {
                Some(child) => {
                    // rawler keeps the last box of a kind in its parent:
                    // a later mdia, minf or stbl replaces the sample tables,
                    // a later stsd the CTMD box.
                    match (child, self.traks.last_mut()) {
                        (BoxKind::Trak, _) => self.traks.push(Trak::default()),
                        (BoxKind::Mdia | BoxKind::Minf | BoxKind::Stbl, Some(t)) => {
                            *t = Trak::default()
                        }
                        (BoxKind::Stsd, Some(t)) => t.ctmd = false,
                        _ => {}
                    }
                    self.children(child, h)?;
                }
                // rawler reads nothing of another uuid box in moov and goes
                // on right after its header (moov.rs): its contents are read
                // as boxes of moov's own.
                None if kind == BoxKind::Moov && &h.typ == b"uuid" => {
                    at += h.len;
                    continue;
                }
                None => self.leaf(kind, h)?,
            }
            at = h.at + h.size;
        }
        Ok(())
    }

    /// Check a box rawler reads more of than its header, `h`, inside a box
    /// of kind `parent`; it lies inside the file.
    fn leaf(&mut self, parent: BoxKind, h: &BoxHead) -> Result<(), ContainerError> {
        let bytes = self.bytes;
        let from = (h.at + h.len) as usize;
        let data = &bytes[from..(h.at + h.size) as usize];
        let be = Order(false);
        let trak = self.traks.last_mut();
        match (parent, &h.typ) {
            (BoxKind::Stbl, b"stts") => {
                table(h, data, 8, 8)?;
            }
            (BoxKind::Stbl, b"stsc") => {
                let n = table(h, data, 8, 12)?;
                if let Some(t) = trak {
                    t.stsc = Some((from + 8, n));
                }
            }
            (BoxKind::Stbl, b"co64") => {
                let n = table(h, data, 8, 8)?;
                if let Some(t) = trak {
                    t.co64 = Some((from + 8, n));
                }
            }
            (BoxKind::Stbl, b"stsz") => {
                // rawler reserves room for every sample's size even when
                // all share one; each sample is at least a byte of the file.
                let len = bytes.len() as u64;
                let size = be.u32(data, 4);
                let n = match size {
                    Some(0) => table(h, data, 12, 4)?,
                    _ => table(h, data, 12, 0)?,
                };
                if n as u64 > len {
                    return Err(ContainerError::malformed(format!(
                        "malformed BMFF structure: the stsz box at byte {} claims {n} samples, more than the file's {len} bytes could hold",
                        h.at
                    )));
                }
                if let (Some(t), Some(size)) = (trak, size) {
                    t.stsz = Some((size, n, from + 12));
                }
            }
            (BoxKind::Stsd, b"CTMD") => {
                table(h, data, 12, 8)?;
                if let Some(t) = trak {
                    t.ctmd = true;
                }
            }
            (BoxKind::Craw, b"CMP1") => {
                let (Some(w), Some(ht)) = (be.u32(data, 8), be.u32(data, 12)) else {
                    return Err(ContainerError::malformed(format!(
                        "malformed BMFF structure: the CMP1 box at byte {} is too short to hold the image's dimensions",
                        h.at
                    )));
                };
                if let Some(what) = too_many_pixels(w as u64, ht as u64) {
                    return Err(ContainerError::damaged(format!(
                        "the CR3's CMP1 box at byte {} claims {what}: its header is damaged",
                        h.at
                    )));
                }
            }
            (BoxKind::Cr3Desc, b"CMT1" | b"CMT2" | b"CMT3" | b"CMT4") => {
                self.cmt += 1;
                if self.cmt > MAX_CMT_BOXES {
                    return Err(ContainerError::malformed(format!(
                        "malformed CR3 structure: more than {MAX_CMT_BOXES} CMT boxes"
                    )));
                }
                check_tiff(data, &SUB_IFD_TAGS, Notes::Skip, true).map_err(|e| {
                    e.within(format!("in the CR3's {} box at byte {}", h.name(), h.at))
                })?;
            }
            _ => {}
        }
        Ok(())
    }

    /// The CTMD records of `trak`'s first sample, which rawler's CR3
    /// decoder reads as Canon's metadata (decoders/cr3.rs, `read_ctmd`),
    /// found the way `StblBox::get_sample_offset(1)` finds it (stbl.rs and
    /// stsc.rs, with the wrapping arithmetic of a release build; where
    /// rawler would panic, it reads nothing).
    fn check_ctmd(&self, trak: &Trak) -> Result<(), ContainerError> {
        let (true, Some((sc_at, sc_n)), Some((size, n, sizes_at)), Some((co_at, co_n))) =
            (trak.ctmd, trak.stsc, trak.stsz, trak.co64)
        else {
            return Ok(());
        };
        let (b, be) = (self.bytes, Order(false));
        // Each stsc entry's first sample, as `StscBox::read_box` computes it.
        let mut entries = Vec::with_capacity(sc_n as usize);
        let (mut first, mut per_chunk) = (1u32, 0u32);
        for i in 0..sc_n as usize {
            let (Some(chunk), Some(spc)) =
                (be.u32(b, sc_at + 12 * i), be.u32(b, sc_at + 12 * i + 4))
            else {
                return Ok(());
            };
            if i > 0 {
                first = first.wrapping_add(chunk.wrapping_sub(first).wrapping_mul(per_chunk));
            }
            per_chunk = spc;
            entries.push((first, chunk, spc));
        }
        // `get_entry_for_sample(1)`: the same search, over the same values.
        let (first, chunk, spc) = match entries.binary_search_by(|e| e.0.cmp(&1)) {
            Ok(i) => entries[i],
            Err(0) => return Ok(()),
            Err(i) => entries[i - 1],
        };
        if spc == 0 {
            return Ok(());
        }
        let chunk = chunk.wrapping_add(0u32.wrapping_sub(first.wrapping_sub(1)) / spc);
        let in_chunk = 1u32.wrapping_sub(first) % spc;
        if chunk == 0 || chunk > co_n || (in_chunk > 0 && size == 0) {
            return Ok(());
        }
        let Some(chunk_at) = (be.u32(b, co_at + 8 * (chunk as usize - 1)))
            .zip(be.u32(b, co_at + 8 * (chunk as usize - 1) + 4))
            .map(|(hi, lo)| (hi as u64) << 32 | lo as u64)
        else {
            return Ok(());
        };
        let sample_size = match size {
            0 if n == 0 => return Ok(()),
            0 => match be.u32(b, sizes_at) {
                Some(s) => s,
                None => return Ok(()),
            },
            s => s,
        };
        let at = chunk_at.wrapping_add(in_chunk.wrapping_mul(size) as u64);
        let Some(sample) = usize::try_from(at)
            .ok()
            .and_then(|a| b.get(a..a.checked_add(sample_size as usize)?))
        else {
            return Ok(());
        };
        check_ctmd_records(sample, at as usize)
    }
}

/// A box's table: a 32-bit big-endian entry count ending at byte `fixed` of
/// its contents `data`, then entries of `per` bytes; rawler reserves room
/// for them all before reading any. The count.
fn table(h: &BoxHead, data: &[u8], fixed: usize, per: u64) -> Result<u32, ContainerError> {
    let Some(n) = Order(false).u32(data, fixed - 4) else {
        return Err(ContainerError::malformed(format!(
            "malformed BMFF structure: the {} box at byte {} is too short to hold its entry count",
            h.name(),
            h.at
        )));
    };
    if fixed as u64 + per * n as u64 > data.len() as u64 {
        return Err(ContainerError::malformed(format!(
            "malformed BMFF structure: the {} box at byte {} lists {n} entries, more than its {} bytes hold",
            h.name(),
            h.at,
            h.size
        )));
    }
    Ok(n)
}

/// Canon's CTMD records in `sample` (at byte `at` of the file): 32-bit
/// little-endian size, type, 6 more header bytes, payload. rawler reserves
/// each payload before it reads it (`ByteStream::get_bytes`), keeps the last
/// record of each type, and parses the EXIF (0x8769) block of record 7 and
/// the MakerNote (0x927C) blocks of records 7, 8 and 9 as TIFF (decoders/
/// cr3.rs, `Ctmd::new` and `read_cr3_metadata`; a second block with the
/// same tag in a record is a panic before any is parsed).
fn check_ctmd_records(sample: &[u8], at: usize) -> Result<(), ContainerError> {
    let le = Order(true);
    let mut last = [None; 3];
    let mut p = 0;
    while sample.len() - p >= 12 {
        let (Some(size), Some(kind)) = (le.u32(sample, p), le.u16(sample, p + 4)) else {
            break;
        };
        let left = sample.len() - p;
        if size < 12 || size as usize > left {
            return Err(ContainerError::malformed(format!(
                "malformed CR3 metadata: the CTMD record at byte {} claims {size} bytes, but its sample has {left} left",
                at + p
            )));
        }
        if let 7..=9 = kind {
            last[kind as usize - 7] = Some((p, size as usize));
        }
        p += size as usize;
    }
    for (kind, (p, size)) in (7..).zip(last).filter_map(|(k, r)| Some((k, r?))) {
        let payload = &sample[p + 12..p + size];
        let mut seen = Vec::new();
        let mut q = 0;
        while payload.len() - q >= 8 {
            let (Some(sz), Some(tag)) = (le.u32(payload, q), le.u16(payload, q + 4)) else {
                break;
            };
            let sz = sz as usize;
            // rawler ends the record's blocks at one that does not fit
            if sz < 8 || sz > payload.len() - q {
                break;
            }
            let tiff = tag == 0x927C || (tag == 0x8769 && kind == 7);
            if tiff && !seen.contains(&tag) {
                seen.push(tag);
                check_tiff(&payload[q + 8..q + sz], &SUB_IFD_TAGS, Notes::Skip, false).map_err(
                    |e| {
                        e.within(format!(
                            "in the CR3's CTMD record {kind} at byte {}",
                            at + p
                        ))
                    },
                )?;
            }
            q += sz;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::container::check;
    use crate::container::testutil::tiff;

    /// An ISO BMFF box.
    fn bx(typ: &[u8; 4], body: &[u8]) -> Vec<u8> {
        let mut b = (8 + body.len() as u32).to_be_bytes().to_vec();
        b.extend_from_slice(typ);
        b.extend_from_slice(body);
        b
    }

    fn be32s(values: &[u32]) -> Vec<u8> {
        values.iter().flat_map(|v| v.to_be_bytes()).collect()
    }

    /// A CR3 in miniature: ftyp; moov with Canon's box of CMT1 (`cmt1`), a
    /// raw trak (CRAW with CMP1 of `w` x `h`) and a CTMD trak whose sample
    /// (`ctmd`, in mdat) is found through stsc, stsz and co64; mdat.
    fn cr3(cmt1: &[u8], w: u32, h: u32, stts: u32, ctmd: &[u8]) -> Vec<u8> {
        let ftyp = bx(b"ftyp", b"crx \0\0\0\x01crx isom");
        let mut desc = b"\0\0\0\0uuid".to_vec();
        desc.extend_from_slice(&CR3_DESC_UUID);
        desc.extend_from_slice(&bx(b"CMT1", cmt1));
        let n = desc.len() as u32;
        desc[..4].copy_from_slice(&n.to_be_bytes());
        let trak = |sample: Vec<u8>, chunk_at: u32| {
            let stbl = [
                bx(b"stsd", &[vec![0; 8], sample].concat()),
                bx(b"stts", &be32s(&[0, stts, 1, 1])),
                bx(b"stsc", &be32s(&[0, 1, 1, 1, 1])),
                bx(b"stsz", &be32s(&[0, ctmd.len() as u32, 1])),
                bx(b"co64", &be32s(&[0, 1, 0, chunk_at])),
            ]
            .concat();
            bx(b"trak", &bx(b"mdia", &bx(b"minf", &bx(b"stbl", &stbl))))
        };
        let mut cmp1 = be32s(&[0, 0, w, h, 512, 512]);
        cmp1.resize(48, 0);
        let craw = bx(b"CRAW", &[vec![0; 82], bx(b"CMP1", &cmp1)].concat());
        let ctmd_box = bx(b"CTMD", &[vec![0; 8], be32s(&[1, 0, 8])].concat());
        let moov = |chunk_at| {
            let body = [
                desc.clone(),
                trak(craw.clone(), chunk_at),
                trak(ctmd_box.clone(), chunk_at),
            ];
            bx(b"moov", &body.concat())
        };
        let chunk_at = (ftyp.len() + moov(0).len() + 8) as u32;
        [ftyp, moov(chunk_at), bx(b"mdat", ctmd)].concat()
    }

    /// A CTMD record: size, type, 6 bytes, payload.
    fn record(kind: u16, payload: &[u8]) -> Vec<u8> {
        let mut r = (12 + payload.len() as u32).to_le_bytes().to_vec();
        r.extend_from_slice(&kind.to_le_bytes());
        r.extend_from_slice(&[0; 6]);
        r.extend_from_slice(payload);
        r
    }

    /// A CTMD block: size, tag, 2 bytes, data.
    fn block(tag: u16, data: &[u8]) -> Vec<u8> {
        let mut b = (8 + data.len() as u32).to_le_bytes().to_vec();
        b.extend_from_slice(&tag.to_le_bytes());
        b.extend_from_slice(&[0; 2]);
        b.extend_from_slice(data);
        b
    }

    fn ctmd(makernote: &[u8]) -> Vec<u8> {
        [record(1, &[0; 4]), record(8, &block(0x927C, makernote))].concat()
    }

    #[test]
    fn a_well_formed_cr3_passes_and_its_allocations_are_bounded() {
        let good_tiff = tiff(&[(256, 3, 1, 6000), (257, 3, 1, 4000)], 0, &[]);
        let bad_tiff = tiff(&[(256, 3, 1, 4), (700, 7, 1000, 8)], 0, &[]);
        let good = || cr3(&good_tiff, 6000, 4000, 1, &ctmd(&good_tiff));
        assert_eq!(check(&good()), Ok(()));
        // The CMT and CTMD TIFF structures are walked.
        let e = check(&cr3(&bad_tiff, 6000, 4000, 1, &ctmd(&good_tiff)))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("past the end") && e.contains("in the CR3's CMT1 box at byte"),
            "{e}"
        );
        let e = check(&cr3(&good_tiff, 6000, 4000, 1, &ctmd(&bad_tiff)))
            .unwrap_err()
            .to_string();
        assert!(e.contains("in the CR3's CTMD record 8 at byte"), "{e}");
        // Only the first IFD of a CTMD block is read (Canon's next-IFD
        // offsets there are not offsets).
        let junk_next = tiff(&[(256, 3, 1, 4)], 1 << 20, &[]);
        assert_eq!(check(&cr3(&good_tiff, 1, 1, 1, &ctmd(&junk_next))), Ok(()));
        // rawler keeps the last record of a type: a bad one replaced by a
        // good one is never parsed.
        let replaced = [ctmd(&bad_tiff), record(8, &block(0x927C, &good_tiff))].concat();
        assert_eq!(check(&cr3(&good_tiff, 1, 1, 1, &replaced)), Ok(()));
        let replaced = [ctmd(&good_tiff), record(8, &block(0x927C, &bad_tiff))].concat();
        assert!(check(&cr3(&good_tiff, 1, 1, 1, &replaced)).is_err());
        // A CTMD record of 2 GB in a sample of 40 bytes.
        let mut huge = ctmd(&good_tiff);
        huge[16..20].copy_from_slice(&(1u32 << 31).to_le_bytes());
        let e = check(&cr3(&good_tiff, 1, 1, 1, &huge))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("CTMD record at byte") && e.contains("claims 2147483648 bytes"),
            "{e}"
        );
        // A 100,000 x 100,000 image, and an stts of 2^32 - 1 entries.
        let e = check(&cr3(&good_tiff, 100_000, 100_000, 1, &ctmd(&good_tiff)))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("CMP1 box") && e.contains("10000 megapixels"),
            "{e}"
        );
        let e = check(&cr3(&good_tiff, 1, 1, u32::MAX, &ctmd(&good_tiff)))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("the stts box at byte") && e.contains("lists 4294967295 entries"),
            "{e}"
        );
        // A truncated file.
        let mut cut = good();
        cut.truncate(cut.len() - 1);
        assert!(check(&cut)
            .unwrap_err()
            .to_string()
            .contains("runs past the end of the file's"));
    }

    /// The offset of the first box of type `typ` in `b`.
    fn find(b: &[u8], typ: &[u8; 4]) -> usize {
        b.windows(4).position(|w| w == typ).unwrap() - 4
    }

    #[test]
    fn boxes_must_lie_inside_their_parents_and_move_rawler_forward() {
        let t = tiff(&[(256, 3, 1, 4)], 0, &[]);
        let good = cr3(&t, 1, 1, 1, &ctmd(&t));
        // stsz with one size for all samples claims more than the file.
        let mut b = good.clone();
        let at = find(&b, b"stsz");
        b[at + 16..at + 20].copy_from_slice(&u32::MAX.to_be_bytes());
        let e = check(&b).unwrap_err().to_string();
        assert!(e.contains("claims 4294967295 samples"), "{e}");
        // A box of size 0 inside a container: rawler reads it forever.
        let mut b = good.clone();
        let at = find(&b, b"mdia");
        b[at..at + 4].copy_from_slice(&0u32.to_be_bytes());
        let e = check(&b).unwrap_err().to_string();
        assert!(
            e.contains(&format!("the mdia box at byte {at} claims 0 bytes")),
            "{e}"
        );
        // One past the end of its parent.
        let mut b = good.clone();
        let at = find(&b, b"stbl");
        let n = u32::from_be_bytes(b[at..at + 4].try_into().unwrap());
        b[at..at + 4].copy_from_slice(&(n + 1).to_be_bytes());
        let e = check(&b).unwrap_err().to_string();
        assert!(e.contains("runs past the end of the minf box"), "{e}");
        // Another uuid box in moov is not skipped by rawler: what it holds
        // is read as moov's boxes, here one of size 0.
        let mut inner = b"\0\0\0\x20uuid".to_vec();
        inner.extend_from_slice(&[7; 16]);
        inner.extend_from_slice(b"\0\0\0\0free");
        let mut b = bx(b"ftyp", b"crx \0\0\0\x01");
        b.extend_from_slice(&bx(b"moov", &inner));
        let e = check(&b).unwrap_err().to_string();
        assert!(e.contains("the free box at byte 48 claims 0 bytes"), "{e}");
        // rawler parses every CMT box it meets.
        let t = tiff(&[(256, 3, 1, 4)], 0, &[]);
        let cmts = |n| {
            let mut desc = b"\0\0\0\0uuid".to_vec();
            desc.extend_from_slice(&CR3_DESC_UUID);
            for _ in 0..n {
                desc.extend_from_slice(&bx(b"CMT1", &t));
            }
            let len = desc.len() as u32;
            desc[..4].copy_from_slice(&len.to_be_bytes());
            [bx(b"ftyp", b"crx \0\0\0\x01"), bx(b"moov", &desc)].concat()
        };
        assert_eq!(check(&cmts(MAX_CMT_BOXES)), Ok(()));
        let e = check(&cmts(MAX_CMT_BOXES + 1)).unwrap_err().to_string();
        assert!(e.contains("more than 64 CMT boxes"), "{e}");
        // Too many boxes.
        let mut b = bx(b"ftyp", b"crx \0\0\0\x01");
        for _ in 0..MAX_BOXES {
            b.extend_from_slice(&bx(b"free", &[]));
        }
        assert!(check(&b)
            .unwrap_err()
            .to_string()
            .contains("more than 65536 boxes"));
    }

    #[test]
    fn files_that_are_not_bmff_are_refused_only_where_rawler_would_loop() {
        // A TIFF reads as one box of 1.2 GB: past the end, where rawler
        // stops. So does text.
        assert_eq!(check(&tiff(&[(256, 3, 1, 4)], 0, &[])), Ok(()));
        assert_eq!(check(b"\0\0\0\x10junk and more junk"), Ok(()));
        // A moov that runs past the end, holding a box of size 0 (the
        // fuzzer's 19 bytes).
        let e = check(b"\0\0\x2a\xe4moov\0\0\0\0\0\0\x01\0\x05\0\0")
            .unwrap_err()
            .to_string();
        assert!(e.contains("box at byte 8 claims 0 bytes"), "{e}");
        // A 64-bit size whose end wraps around 2^64 sends rawler back.
        let mut b = bx(b"abcd", &[0; 8]);
        b.extend_from_slice(b"\0\0\0\x01abcd");
        b.extend_from_slice(&(u64::MAX - 8).to_be_bytes());
        let e = check(&b).unwrap_err().to_string();
        assert!(
            e.contains("the abcd box at byte 16 claims") && e.contains("loop"),
            "{e}"
        );
    }
}
