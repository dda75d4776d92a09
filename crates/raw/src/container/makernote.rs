//! The vendors' MakerNotes: which of them rawler parses (by the decoder the
//! Make tag picks) and where each decoder finds the IFD in one (vendor
//! prefix, byte order and the base its offsets count from). rawler
//! allocates a MakerNote entry's values as it does any other's, so the
//! MakerNote is walked with `tiff`'s walker, from where that decoder finds
//! it; the layouts are kept here, apart from the generic IFD walk.

use super::lenient::Values;
use super::order::Order;
use super::tiff::{find_entry, Entry, Walk};
use super::ContainerError;

/// Which MakerNotes of a TIFF structure rawler parses.
#[derive(Clone, Copy)]
pub(super) enum Notes {
    /// None (a CR3's TIFF structures).
    Skip,
    /// The file's own: as the decoder rawler picks by the Make tag does.
    ByMake,
    /// A RAF's: its decoder uses `IFD::parse_makernote` (absolute offsets).
    Raf,
}

/// How a decoder of rawler finds the IFD in a MakerNote.
#[derive(Clone, Copy)]
pub(super) enum NoteLayout {
    /// `IFD::parse_makernote` (formats/tiff/ifd.rs, lines 584-660): a vendor
    /// prefix it knows (Olympus, Epson, Fujifilm, Sony, Pentax, Nikon) is
    /// skipped, then an optional II/MM, then the IFD. Its offsets count
    /// from the TIFF header, or with `relative` (Samsung's SRW) from the IFD
    /// itself; Pentax's "PENTAX" and Nikon's "Nikon\0\x02" MakerNotes carry
    /// their own base.
    Prefixed { relative: bool },
    /// Canon's CR2 (decoders/cr2.rs, `new_makernote`, line 468): the IFD is
    /// right at the MakerNote, offsets from the TIFF header.
    Plain,
    /// Olympus' ORF (decoders/orf.rs, `parse_makernote`, lines 52-120): the
    /// IFD after "OLYMP\0..." or "OLYMPUS\0II..." (or "OM SYSTEM...") with
    /// the file's byte order and its sub-IFDs in tag 0x3000, then the
    /// Equipment (0x2010) and ImageProcessing (0x2040) IFDs, whose offsets
    /// count from the MakerNote.
    Olympus,
}

/// Walk the MakerNote `note` of the TIFF structure `bytes` (byte order
/// `order`) the way `layout` says rawler does. rawler allocates each entry's
/// values before reading them, as anywhere else. Where rawler would panic
/// (a MakerNote too short for the prefixes it compares) or read nothing,
/// there is nothing to walk. `spent` carries the IFDs visited and offsets
/// listed by earlier MakerNote walks, counted against [`MAX_IFDS`] and
/// [`MAX_LISTED`], and the entry values rawler would hold so far.
///
/// [`MAX_IFDS`]: super::MAX_IFDS
/// [`MAX_LISTED`]: super::MAX_LISTED
pub(super) fn check_makernote(
    bytes: &[u8],
    order: Order,
    note: &Entry,
    layout: NoteLayout,
    spent: &mut (usize, u64, Values),
) -> Result<(), ContainerError> {
    let at = note.at;
    let mut w = NoteWalk { bytes, at, spent };
    let relative = match layout {
        NoteLayout::Plain => return w.walk(0, order, at as u64, &[]),
        NoteLayout::Olympus => None,
        NoteLayout::Prefixed { relative } => Some(relative),
    };
    // Both other parsers take the MakerNote as UNDEFINED bytes (any other
    // type is an error), and compare its first 9 bytes with a prefix before
    // reading any IFD: a panic on a shorter one.
    let data = bytes.get(at..at.saturating_add(note.count as usize));
    let Some(data) = data.filter(|d| note.kind == 7 && d.len() >= 9) else {
        return Ok(());
    };
    let is = |prefix: &[u8]| data.starts_with(prefix);
    let mut off = 0;
    if is(b"OLYMP") {
        off += 8;
        if is(b"OLYMPUS") {
            off += 4;
        }
    }
    match relative {
        None => w.olympus(data, order, off),
        Some(relative) => w.prefixed(data, order, off, relative),
    }
}

/// A MakerNote's IFDs walked as rawler reads them, the walk's budget
/// carried from one to the next ([`check_makernote`]).
struct NoteWalk<'a, 's> {
    bytes: &'a [u8],
    /// The MakerNote's byte offset.
    at: usize,
    spent: &'s mut (usize, u64, Values),
}

impl NoteWalk<'_, '_> {
    /// The IFD at `ifd` of the structure whose offsets count from `base`.
    fn walk(
        &mut self,
        base: usize,
        o: Order,
        ifd: u64,
        sub_tags: &'static [u16],
    ) -> Result<(), ContainerError> {
        let Some(b) = self.bytes.get(base..) else {
            return Ok(());
        };
        let mut walk = Walk::new(b, o, sub_tags, true);
        (walk.visits, walk.listed, walk.values) = *self.spent;
        let walked = walk.ifd(ifd, false);
        *self.spent = (walk.visits, walk.listed, walk.values);
        let at = self.at;
        walked.map_err(|e| {
            if base == 0 {
                e.within(format!("in the MakerNote at byte {at}"))
            } else {
                e.within(format!(
                    "in the MakerNote at byte {at}, whose offsets count from byte {base}"
                ))
            }
        })
    }

    /// Olympus's MakerNote (and OM System's): the main IFD `off` bytes in,
    /// and the camera-settings and image-processing sub-IFDs it points to.
    fn olympus(&mut self, data: &[u8], order: Order, mut off: usize) -> Result<(), ContainerError> {
        if data.starts_with(b"OM SYSTEM") {
            off += 16;
            // asserted by rawler
            if data.get(12..14) != Some(&b"II"[..]) {
                return Ok(());
            }
        }
        let main = (self.at + off) as u64;
        self.walk(0, order, main, &[0x3000])?;
        // rawler reads 4 bytes at the entry's value for the offset
        for (tag, wanted) in [(0x2010, true), (0x2040, off == 12 || off == 16)] {
            let Some(e) = find_entry(self.bytes, order, main, tag).filter(|_| wanted) else {
                continue;
            };
            match order.u32(self.bytes, e.at) {
                Some(0) if tag == 0x2040 => {}
                Some(ifd) => self.walk(self.at, order, ifd as u64, &[])?,
                None => {}
            }
        }
        Ok(())
    }

    /// The MakerNotes whose IFD follows a maker's prefix (Epson, Fujifilm,
    /// Sony, AOC, Pentax, Nikon) and perhaps a byte-order marker; offsets
    /// count from the MakerNote when `relative`.
    fn prefixed(
        &mut self,
        data: &[u8],
        order: Order,
        mut off: usize,
        relative: bool,
    ) -> Result<(), ContainerError> {
        let at = self.at;
        let is = |prefix: &[u8]| data.starts_with(prefix);
        if is(b"EPSON") {
            off += 8;
        }
        if is(b"FUJIFILM") {
            off += 12;
        }
        if is(b"SONY DSC ") {
            off += 12;
        }
        if is(b"AOC\0") {
            off += 4;
        }
        let marker = |off: usize| data.get(off..off + 2);
        if is(b"PENTAX") {
            // Offsets count from the MakerNote; its IFD is 10 bytes in.
            off += 8;
            let Some(m) = marker(off) else {
                return Ok(());
            };
            return self.walk(at, Order(m == b"II"), 10, &[]);
        }
        if is(b"Nikon\0\x02") {
            // An embedded TIFF header 10 bytes in: offsets count from it, and
            // its IFD is read at 8 whatever the header says.
            off += 10;
            let Some(m) = marker(off) else {
                return Ok(());
            };
            return self.walk(at + 10, Order(m == b"II"), 8, &[]);
        }
        let mut o = order;
        for (m, little) in [(b"II", true), (b"MM", false)] {
            let Some(here) = marker(off) else {
                return Ok(());
            };
            if here == m {
                off += 2;
                o = Order(little);
            }
        }
        if relative {
            self.walk(at + off, o, 0, &[])
        } else {
            self.walk(0, o, (at + off) as u64, &[])
        }
    }
}

impl Walk<'_> {
    /// How the decoder rawler picks for this file (`get_decoder`,
    /// decoders/mod.rs, lines 980-1022) parses its MakerNote, if it does.
    pub(super) fn note_layout(&self) -> Option<NoteLayout> {
        if self.dng_chain {
            return None;
        }
        if let Some(Some("DCS560C")) = self.model.as_ref().map(Option::as_deref) {
            return Some(NoteLayout::Plain);
        }
        let make = self.make.as_ref()?.as_deref()?.trim_end();
        Some(match make {
            // decoders/cr2.rs, `new_makernote`
            "Canon" => NoteLayout::Plain,
            // decoders/{pef,arw,erf,kdc,nef}.rs: `parse_makernote`, Absolute
            "PENTAX"
            | "PENTAX Corporation"
            | "RICOH IMAGING COMPANY, LTD."
            | "SONY"
            | "SEIKO EPSON CORP."
            | "EASTMAN KODAK COMPANY"
            | "Eastman Kodak Company"
            | "Nikon"
            | "NIKON CORPORATION" => NoteLayout::Prefixed { relative: false },
            // decoders/srw.rs: `parse_makernote`, RelativeToIFD
            "SAMSUNG" => NoteLayout::Prefixed { relative: true },
            // decoders/orf.rs, `parse_makernote`
            "OLYMPUS IMAGING CORP."
            | "OLYMPUS CORPORATION"
            | "OLYMPUS OPTICAL CO.,LTD"
            | "OM Digital Solutions" => NoteLayout::Olympus,
            _ => return None,
        })
    }
}

#[cfg(test)]
mod tests {
    use crate::container::check;
    use crate::container::testutil::tiff;

    /// A little-endian TIFF whose IFD0 has Make `make` and an EXIF IFD with
    /// the MakerNote `note` (UNDEFINED); the note's offset.
    fn with_note(make: &str, note: &[u8]) -> (Vec<u8>, u32) {
        let mut tail = make.as_bytes().to_vec();
        tail.push(0);
        if tail.len() % 2 == 1 {
            tail.push(0);
        }
        // IFD0 (2 entries) ends at 38; the EXIF IFD follows Make.
        let exif_at = 38 + tail.len() as u32;
        let note_at = exif_at + 18;
        tail.extend_from_slice(&1u16.to_le_bytes());
        tail.extend_from_slice(&37500u16.to_le_bytes());
        tail.extend_from_slice(&7u16.to_le_bytes());
        tail.extend_from_slice(&(note.len() as u32).to_le_bytes());
        tail.extend_from_slice(&note_at.to_le_bytes());
        tail.extend_from_slice(&0u32.to_le_bytes());
        tail.extend_from_slice(note);
        let e = [(271, 2, make.len() as u32 + 1, 38), (34665, 4, 1, exif_at)];
        (tiff(&e, 0, &tail), note_at)
    }

    /// An IFD of one entry (tag 1, UNDEFINED, `count` values at `value`)
    /// and next-IFD offset 0, then 8 bytes; big-endian if `be`.
    fn ifd1(be: bool, count: u32, value: u32) -> Vec<u8> {
        let w16 = |v: u16| if be { v.to_be_bytes() } else { v.to_le_bytes() };
        let w32 = |v: u32| if be { v.to_be_bytes() } else { v.to_le_bytes() };
        let mut b = w16(1).to_vec();
        b.extend_from_slice(&w16(1));
        b.extend_from_slice(&w16(7));
        b.extend_from_slice(&w32(count));
        b.extend_from_slice(&w32(value));
        b.extend_from_slice(&[0; 12]);
        b
    }

    #[test]
    fn a_nikon_makernote_is_walked_from_its_own_tiff_header() {
        // "Nikon\0\x02\x10\0\0", then a big-endian TIFF header whose offsets
        // the IFD at its byte 8 uses: 8 values right after that IFD (26).
        let nikon = |count: u32| {
            let mut n = b"Nikon\0\x02\x10\0\0MM\0\x2a\0\0\0\x08".to_vec();
            n.extend_from_slice(&ifd1(true, count, 26));
            n
        };
        assert_eq!(check(&with_note("NIKON CORPORATION", &nikon(8)).0), Ok(()));
        let (bad, at) = with_note("NIKON CORPORATION", &nikon(u32::MAX - 15));
        let e = check(&bad).unwrap_err().to_string();
        assert!(
            e.contains("tag 1's 4294967280 values at byte 26 run past the end")
                && e.contains(&format!(
                    "in the MakerNote at byte {at}, whose offsets count from byte {}",
                    at + 10
                )),
            "{e}"
        );
        // Offset 26 from the file's header would still lie inside it.
        let (wrong_base, _) = with_note("NIKON CORPORATION", &nikon(40));
        assert!(check(&wrong_base).is_err());
        // The decoder rawler picks for this Make (RW2) does not parse
        // MakerNotes, and a DNG's does not either: nothing to walk.
        assert_eq!(check(&with_note("Panasonic", &nikon(u32::MAX)).0), Ok(()));
        let (mut dng, _) = with_note("NIKON CORPORATION", &nikon(u32::MAX));
        dng[8 + 2 + 2..8 + 2 + 4].copy_from_slice(&50706u16.to_le_bytes());
        assert_eq!(check(&dng), Ok(()));
        // Shorter than the prefixes rawler compares: it panics first.
        assert_eq!(
            check(&with_note("NIKON CORPORATION", b"Nikon\0\x02").0),
            Ok(())
        );
    }

    #[test]
    fn makernotes_are_walked_with_each_vendors_base() {
        // Sony: a prefix and an IFD whose offsets count from the file's
        // header; Samsung: no prefix, offsets from the IFD itself.
        let sony = |value: u32| {
            let mut n = b"SONY DSC \0\0\0".to_vec();
            n.extend_from_slice(&ifd1(false, 8, value));
            n
        };
        let (ok, at) = with_note("SONY", &sony(0));
        assert_eq!(check(&ok), Ok(()));
        let (bad, _) = with_note("SONY", &sony(at + 12 + 18 + 4));
        let e = check(&bad).unwrap_err().to_string();
        assert!(
            e.contains(&format!("(in the MakerNote at byte {at})")),
            "{e}"
        );
        // 18: the 8 bytes after the IFD, counted from the IFD.
        assert_eq!(check(&with_note("SAMSUNG", &ifd1(false, 8, 18)).0), Ok(()));
        let (bad, at) = with_note("SAMSUNG", &ifd1(false, 8, 22));
        let e = check(&bad).unwrap_err().to_string();
        assert!(e.contains(&format!("count from byte {at}")), "{e}");
        // The same value from the file's header is fine for Sony.
        assert_eq!(check(&with_note("SONY", &ifd1(false, 8, 22)).0), Ok(()));
        // Pentax: "PENTAX \0" and a byte order, the IFD 10 bytes in, offsets
        // from the MakerNote.
        let pentax = |count: u32| {
            let mut n = b"PENTAX \0MM".to_vec();
            n.extend_from_slice(&ifd1(true, count, 28));
            n
        };
        assert_eq!(check(&with_note("PENTAX", &pentax(8)).0), Ok(()));
        assert!(check(&with_note("PENTAX", &pentax(9)).0)
            .unwrap_err()
            .to_string()
            .contains("run past the end"));
        // Canon: the IFD right at the MakerNote.
        let (ok, at) = with_note("Canon", &ifd1(false, 4, 0));
        assert_eq!(check(&ok), Ok(()));
        let (bad, _) = with_note("Canon", &ifd1(false, 5, at + 18 + 4));
        assert!(check(&bad)
            .unwrap_err()
            .to_string()
            .contains("in the MakerNote"));
        // rawler parses one MakerNote; 1100 of them are walked within the
        // budget of one walk (here an empty IFD each).
        let notes = |n: u32| {
            let tail_at = 8 + 2 + 12 * (n + 1) + 4;
            let mut e = vec![(271, 2, 6, tail_at)];
            e.extend(vec![(37500, 7, 6, tail_at + 6); n as usize]);
            tiff(&e, 0, b"Canon\0\0\0\0\0\0\0")
        };
        assert_eq!(check(&notes(1000)), Ok(()));
        let e = check(&notes(1100)).unwrap_err().to_string();
        assert!(
            e.contains("more than 1024 IFDs") && e.contains("MakerNote"),
            "{e}"
        );
    }

    #[test]
    fn olympus_makernotes_and_their_equipment_ifd_are_walked() {
        // "OLYMPUS\0II\x03\0", the main IFD 12 bytes in with an Equipment
        // IFD (0x2010) 32 bytes into the MakerNote, whose offsets count from
        // the MakerNote.
        let olympus = |count: u32| {
            let mut n = b"OLYMPUS\0II\x03\0".to_vec();
            n.extend_from_slice(&1u16.to_le_bytes());
            n.extend_from_slice(&0x2010u16.to_le_bytes());
            n.extend_from_slice(&4u16.to_le_bytes());
            n.extend_from_slice(&1u32.to_le_bytes());
            n.extend_from_slice(&32u32.to_le_bytes());
            n.extend_from_slice(&[0; 6]);
            assert_eq!(n.len(), 32);
            n.extend_from_slice(&ifd1(false, count, 50));
            n
        };
        let make = "OLYMPUS IMAGING CORP.";
        assert_eq!(check(&with_note(make, &olympus(8)).0), Ok(()));
        let (bad, at) = with_note(make, &olympus(9));
        let e = check(&bad).unwrap_err().to_string();
        assert!(e.contains(&format!("count from byte {at}")), "{e}");
    }
}
