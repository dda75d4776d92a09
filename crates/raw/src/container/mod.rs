//! A cheap look at a RAW container (TIFF-based: DNG, ARW, NEF, CR2, KDC,
//! ...; RAF, MRW, CR3, QuickTake) before rawler decodes it, so that a
//! malformed or hostile file is refused with one line instead of costing the
//! user their memory.
//!
//! rawler follows IFD chains without remembering where it has been (an IFD
//! whose next-IFD offset points back at itself makes it allocate without
//! limit) and trusts the dimensions a file claims. This walk reads only the
//! IFD entries, in bounded steps, and checks:
//!
//! - every IFD (the root chain, SubIFDs, EXIF, GPS and interoperability IFDs)
//!   lies inside the file and is visited once: a cycle is refused (a missing
//!   next-IFD offset reads as 0, as in rawler: Canon's CR3 metadata omits
//!   it);
//! - at most [`MAX_IFDS`] IFDs and [`MAX_ENTRIES`] entries per IFD;
//! - every image's claimed width x height is at most [`MAX_PIXELS`], so a
//!   decode can never ask for more than a few GB;
//! - strip and tile extents lie inside the file and past the 8-byte header;
//! - in a DNG, an uncompressed image's strips (or each tile) hold the bits
//!   per sample it claims, to within a few bytes of padding (BitsPerSample 8
//!   over 14-bit data would decode to black, 12 over 14 to noise);
//! - in a DNG, each lossless-JPEG strip or tile is a whole stream (markers
//!   up to its scan, coded data ending in a marker inside its byte count:
//!   rawler decodes a cut one as constant planes), and a tile's frame is
//!   TileWidth x TileLength samples (rawler decodes another as zeros);
//!   tiles are at least one pixel and their padded area within the pixel
//!   bound;
//! - every entry's values lie inside the file, whatever their type: rawler
//!   allocates an entry's values (up to 4 GB for a count of 2^32 - 1) before
//!   reading them, and reads a type it does not know as bytes;
//! - the MakerNote, where the decoder rawler picks (by the Make tag) parses
//!   it as an IFD, is walked the way that decoder finds it (vendor prefix,
//!   byte order and the base its offsets count from), for the same reason;
//! - what rawler reads as an IFD although it need not be one (an ICC
//!   profile's data, UNDEFINED or unknown-typed SubIFD entries, a Kodak
//!   IFD, Panasonic's CameraIFD, Sony's encrypted SR2 block, which is
//!   decrypted for the purpose) is read as rawler reads it, tolerating what
//!   it tolerates, and refused only where an entry would make it allocate
//!   more than the file could hold; and all the entry values rawler would
//!   keep add up to at most twice the file (512 MiB for small files).
//!
//! RAF files start with Fujifilm's own header, which points at two TIFF
//! structures rawler parses (the preview JPEG's EXIF and the raw IFDs with
//! their FujiIFD); both are walked the same way, and the MakerNote with
//! them. MRW's block chain and its IFD are checked too.
//!
//! rawler tries every file it does not recognise by its magic as ISO BMFF
//! (boxes) before it tries TIFF, and allocates from the sizes and counts its
//! boxes claim: CR3 files (and any file whose first bytes read as boxes rawler
//! would loop over) get their boxes walked (`check_bmff`). QuickTake
//! files get their claimed dimensions checked. rawler's panics stay caught
//! either way.
//!
//! Each format has its own submodule: `tiff` walks a TIFF structure's IFDs
//! and checks its images, `lenient` follows rawler's own tolerant reading of
//! an IFD and what it allocates, `makernote` finds and walks the vendors'
//! MakerNotes the way each of rawler's decoders does, `raf` and `mrw` find
//! the TIFF structures inside Fujifilm's and Minolta's containers, `bmff`
//! walks ISO BMFF boxes and a CR3's metadata, and `qtk` bounds QuickTake
//! dimensions. What they share lives in two modules of its own, so none of
//! them imports this one: `limits` (the public limits and the pixel bound)
//! and `order` (the byte-order reader). This module holds [`check`], which
//! picks the checks by the file's magic, and the tag look-ups pgrf makes
//! after it.

mod bmff;
mod error;
mod lenient;
pub(crate) mod limits;
mod makernote;
mod mrw;
mod order;
mod qtk;
mod raf;
mod tiff;

use bmff::check_bmff;
pub use error::{Cause, ContainerError};
use makernote::Notes;
use mrw::check_mrw;
use order::Order;
use qtk::check_qtk;
use raf::check_raf;
use tiff::{check_tiff, SUB_IFD_TAGS};

pub use limits::{MAX_BOXES, MAX_ENTRIES, MAX_IFDS, MAX_LISTED, MAX_PIXELS};

/// Check the container of `bytes` (see the module documentation); `Ok` for
/// files of no format checked here. The message names the problem, for one
/// line.
pub fn check(bytes: &[u8]) -> Result<(), ContainerError> {
    if bytes.starts_with(b"FUJIFILM") {
        return check_raf(bytes);
    }
    if bytes.starts_with(b"\0MRM") {
        return check_mrw(bytes);
    }
    if bytes.starts_with(b"qktk") || bytes.starts_with(b"qktn") {
        return check_qtk(bytes);
    }
    // rawler's `get_decoder` (decoders/mod.rs) claims ARRI, CRW (CIFF) and
    // X3F files by their magic before it tries BMFF; every other file it
    // parses as BMFF boxes first, TIFF files included, then as TIFF.
    let claimed = bytes.starts_with(b"ARRI")
        || bytes.starts_with(b"FOVb")
        || bytes.get(6..14) == Some(&b"HEAPCCDR"[..]);
    if !claimed {
        check_bmff(bytes)?;
    }
    check_tiff(bytes, &SUB_IFD_TAGS, Notes::ByMake, true)
}

/// EXIF AmbientTemperature (tag 0x9400, a signed rational, degrees Celsius)
/// of a TIFF-based file: in the first IFD's EXIF IFD, where cameras that
/// record it and the DNGs pgrf writes keep it. rawler does not read it.
/// `None` for other files, a missing tag or a value no sensor has (outside
/// -273..1000, or a zero denominator). Call after [`check`], which makes
/// sure the offsets lie inside the file.
pub fn exif_temperature(bytes: &[u8]) -> Option<f32> {
    let order = match bytes.get(..2)? {
        b"II" => Order(true),
        b"MM" => Order(false),
        _ => return None,
    };
    let ifd0 = order.u32(bytes, 4)? as u64;
    let exif = tiff::find_entry(bytes, order, ifd0, 34665)?;
    let exif_ifd = order.u32(bytes, exif.at)? as u64;
    let t = tiff::find_entry(bytes, order, exif_ifd, 0x9400)?;
    if t.kind != 10 || t.count < 1 {
        return None;
    }
    let n = order.u32(bytes, t.at)? as i32;
    let d = order.u32(bytes, t.at + 4)? as i32;
    let c = (d != 0).then(|| n as f64 / d as f64)?;
    (-273.15..=1000.0).contains(&c).then_some(c as f32)
}

/// The first entry `tag` of a TIFF-based file's IFD0 or its SubIFDs
/// (where DNG writers put the raw image's tags: pgrf in IFD0, Adobe's
/// converter in a SubIFD), with the file's byte order.
fn raw_ifd_entry(bytes: &[u8], tag: u16) -> Option<(Order, tiff::Entry)> {
    let order = match bytes.get(..2)? {
        b"II" => Order(true),
        b"MM" => Order(false),
        _ => return None,
    };
    let ifd0 = order.u32(bytes, 4).map(u64::from)?;
    let mut ifds = vec![ifd0];
    if let Some(sub) = tiff::find_entry(bytes, order, ifd0, 330) {
        if sub.kind == 4 || sub.kind == 13 {
            for k in 0..sub.count.min(16) as usize {
                if let Some(o) = order.u32(bytes, sub.at + 4 * k) {
                    ifds.push(o as u64);
                }
            }
        }
    }
    ifds.iter()
        .find_map(|&ifd| tiff::find_entry(bytes, order, ifd, tag))
        .map(|e| (order, e))
}

/// The DNG MaskedAreas tag (50830) of a TIFF-based file: rectangles of the
/// readout (top, left, bottom, right) whose pixels are shielded from
/// light ([`crate::masked`]). rawler parses the tag but does not pass it
/// on. Empty without the tag or for one that is unusable (not SHORT or
/// LONG, a count that is not a multiple of 4, values past the file):
/// the metadata's black level is used then, as before.
pub fn masked_areas(bytes: &[u8]) -> Vec<crate::masked::Area> {
    let Some((order, e)) = raw_ifd_entry(bytes, 50830) else {
        return Vec::new();
    };
    if !(e.kind == 3 || e.kind == 4) || e.count % 4 != 0 || e.count > 4 * 16 {
        return Vec::new();
    }
    let mut areas = Vec::new();
    for k in 0..e.count / 4 {
        let v = |i: u64| e.value(bytes, order, 4 * k + i).map(|x| x as usize);
        let (Some(top), Some(left), Some(bottom), Some(right)) = (v(0), v(1), v(2), v(3)) else {
            return Vec::new();
        };
        areas.push(crate::masked::Area {
            top,
            left,
            bottom,
            right,
        });
    }
    areas
}

/// The raw IFD's NewRawImageDigest (tag 51111): 16 bytes of MD5, BYTE or
/// UNDEFINED; None when the file has none or it is not 16 bytes.
pub fn raw_digest(bytes: &[u8]) -> Option<[u8; 16]> {
    let (_, e) = raw_ifd_entry(bytes, 51111)?;
    if !(e.kind == 1 || e.kind == 7) || e.count != 16 {
        return None;
    }
    bytes.get(e.at..e.at + 16)?.try_into().ok()
}

/// The DNG NoiseProfile tag (51041) of a TIFF-based file: (S, O) pairs,
/// one for all planes or one per colour plane, such that a pixel's noise
/// variance is S x + O for x its signal normalised to [0, 1] (black 0,
/// white 1). Looked up in IFD0 and its SubIFDs (Adobe's converter puts it
/// in the raw IFD). `Ok(None)` without the tag; `Err` for a tag that is
/// there but unusable (wrong type, a count that is neither 2 nor 2 x
/// planes, negative or non-finite values), named for one line.
pub fn noise_profile(bytes: &[u8], planes: usize) -> Result<Option<Vec<[f64; 2]>>, ContainerError> {
    let Some((order, e)) = raw_ifd_entry(bytes, 51041) else {
        return Ok(None);
    };
    if e.kind != 12 {
        return Err(ContainerError::bad_tag(format!(
            "NoiseProfile (tag 51041) has TIFF type {}, not DOUBLE (12)",
            e.kind
        )));
    }
    if e.count != 2 && e.count != 2 * planes as u64 {
        return Err(ContainerError::bad_tag(format!(
            "NoiseProfile (tag 51041) holds {} values; it needs 2 (one pair for all planes) or {} (a pair per plane)",
            e.count,
            2 * planes
        )));
    }
    let mut pairs = Vec::new();
    for k in 0..e.count as usize / 2 {
        let f = |i: usize| -> Option<f64> {
            let at = e.at + 8 * i;
            let hi = order.u32(bytes, at)? as u64;
            let lo = order.u32(bytes, at + 4)? as u64;
            Some(f64::from_bits(if order.0 {
                (lo << 32) | hi
            } else {
                (hi << 32) | lo
            }))
        };
        let (Some(s), Some(o)) = (f(2 * k), f(2 * k + 1)) else {
            return Err(ContainerError::bad_tag(
                "NoiseProfile (tag 51041) points past the end of the file".into(),
            ));
        };
        if !(s.is_finite() && o.is_finite() && s >= 0.0 && o >= 0.0) {
            return Err(ContainerError::bad_tag(format!(
                "NoiseProfile (tag 51041) pair {} is ({s}, {o}); both must be finite and >= 0",
                k + 1
            )));
        }
        pairs.push([s, o]);
    }
    Ok(Some(pairs))
}

/// Builders of test files that the tests of several formats share.
#[cfg(test)]
mod testutil {
    /// A little-endian TIFF: header, one IFD at byte 8 with `entries`
    /// (tag, type, count, value), next-IFD offset `next`, then `tail`.
    pub(super) fn tiff(entries: &[(u16, u16, u32, u32)], next: u32, tail: &[u8]) -> Vec<u8> {
        let mut b = b"II*\0\x08\0\0\0".to_vec();
        b.extend_from_slice(&le_ifd(entries, next));
        b.extend_from_slice(tail);
        b
    }

    /// A little-endian IFD: the entry count, `entries` (tag, type, count,
    /// value) and the next-IFD offset `next`.
    pub(super) fn le_ifd(entries: &[(u16, u16, u32, u32)], next: u32) -> Vec<u8> {
        let mut b = (entries.len() as u16).to_le_bytes().to_vec();
        for &(t, k, c, v) in entries {
            b.extend_from_slice(&t.to_le_bytes());
            b.extend_from_slice(&k.to_le_bytes());
            b.extend_from_slice(&c.to_le_bytes());
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&next.to_le_bytes());
        b
    }
}
