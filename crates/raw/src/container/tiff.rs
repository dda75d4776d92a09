//! The TIFF structure walk: IFD entries, the depth-first walk over the IFD
//! graph ([`Walk`]) and the checks of each image it finds. Every TIFF-based
//! format (and the TIFF structures inside RAF, MRW and CR3 files) goes
//! through it, so it lives apart from the containers that only locate those
//! structures; the MakerNotes it collects are walked by `makernote`.

use super::lenient::{self, Blob, Values};
use super::limits::{too_many_pixels, MAX_ENTRIES, MAX_IFDS, MAX_LISTED};
use super::makernote::{check_makernote, NoteLayout, Notes};
use super::order::Order;
use super::ContainerError;

pub(super) const SUB_IFD_TAGS: [u16; 4] = [330, 34665, 34853, 40965];
/// The tags rawler's TIFF reader parses as sub-IFDs of the root chain's
/// IFDs (`wellknown_sub_ifd_tags`: SubIFDs, EXIF, GPS and the ICC profile),
/// with the Kodak IFD its CR2 and DCR decoders add: read the way rawler
/// reads them (`lenient`), whatever their type.
const RAWLER_SUB_TAGS: [u16; 5] = [330, 34665, 34853, 34675, 33424];
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
const TAG_MAKE: u16 = 271;
const TAG_MODEL: u16 = 272;
const TAG_MAKERNOTE: u16 = 37500;

/// One IFD entry's values: type, count and where they are.
pub(super) struct Entry {
    pub(super) kind: u16,
    pub(super) count: u64,
    /// Offset of the values (inline ones: inside the entry).
    pub(super) at: usize,
}

/// Bytes per value of a TIFF type. rawler reads a type it does not know
/// (0, or above 13) as bytes, so it is counted as one byte here: its values
/// lie inline or must lie inside the file like any other's.
fn type_size(kind: u16) -> u64 {
    match kind {
        3 | 8 => 2,
        4 | 9 | 11 | 13 => 4,
        5 | 10 | 12 => 8,
        _ => 1,
    }
}

impl Entry {
    /// Value `i` as an unsigned integer (BYTE, SHORT, LONG or IFD types).
    pub(super) fn value(&self, b: &[u8], o: Order, i: u64) -> Option<u64> {
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

    /// An ASCII value as rawler reads it (`TiffAscii::new_from_raw`): up to
    /// the first NUL; `None` for another type (rawler's `as_string`).
    fn ascii(&self, b: &[u8]) -> Option<String> {
        if self.kind != 2 {
            return None;
        }
        let raw = b.get(self.at..self.at.saturating_add(self.count as usize))?;
        let s = raw.split(|&c| c == 0).next().unwrap_or_default();
        Some(
            std::str::from_utf8(s)
                .unwrap_or("!!!INVALID UTF8!!!")
                .to_string(),
        )
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
    tile_width: Option<u64>,
    tile_length: Option<u64>,
    tiles: Vec<u64>,
    tile_counts: Vec<u64>,
}

/// Walk the TIFF structure `bytes` starts with (offsets relative to its
/// first byte), following `sub_tags` to sub-IFDs, then the MakerNotes as
/// `notes` says; `Ok` if it is not TIFF. With `chain` false only the first
/// IFD of the root chain (and its sub-IFDs) is read, as rawler reads a CR3's
/// CTMD blocks.
pub(super) fn check_tiff(
    bytes: &[u8],
    sub_tags: &'static [u16],
    notes: Notes,
    chain: bool,
) -> Result<(), ContainerError> {
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
    let first = order
        .u32(bytes, 4)
        .ok_or_else(|| ContainerError::truncated("truncated TIFF header".into()))?
        as u64;
    let walk = walk_ifds(bytes, order, first, sub_tags, chain)?;
    let layout = match notes {
        Notes::Skip => None,
        Notes::Raf => Some(NoteLayout::Prefixed { relative: false }),
        Notes::ByMake => walk.note_layout(),
    };
    let mut spent = (0, 0, walk.values);
    if let Some(layout) = layout {
        // rawler parses one MakerNote; a file that has many gets them walked
        // within the budget of one walk.
        for note in &walk.notes {
            check_makernote(bytes, order, note, layout, &mut spent)?;
        }
    }
    if matches!(notes, Notes::ByMake) {
        lenient::check_decoder_ifds(bytes, order, &walk.chain, &mut spent.2)?;
    }
    Ok(())
}

/// The last entry with `tag` (rawler keeps the last of a tag) of the IFD at
/// `ifd`, which a walk has found well-formed.
pub(super) fn find_entry(bytes: &[u8], order: Order, ifd: u64, tag: u16) -> Option<Entry> {
    let ifd = usize::try_from(ifd).ok()?;
    let n = order.u16(bytes, ifd)? as usize;
    (0..n.min(MAX_ENTRIES)).rev().find_map(|k| {
        let e_at = ifd + 2 + 12 * k;
        if order.u16(bytes, e_at)? != tag {
            return None;
        }
        let kind = order.u16(bytes, e_at + 2)?;
        let count = order.u32(bytes, e_at + 4)? as u64;
        let at = if type_size(kind).saturating_mul(count) <= 4 {
            e_at + 8
        } else {
            order.u32(bytes, e_at + 8)? as usize
        };
        Some(Entry { kind, count, at })
    })
}

/// Walk the IFDs of a TIFF structure whose offsets are relative to the
/// first byte of `bytes`, from the IFD at `first` (and the IFDs after it if
/// `chain`), and check its images.
pub(super) fn walk_ifds<'a>(
    bytes: &'a [u8],
    order: Order,
    first: u64,
    sub_tags: &'static [u16],
    chain: bool,
) -> Result<Walk<'a>, ContainerError> {
    let mut walk = Walk::new(bytes, order, sub_tags, false);
    walk.follow_next = chain;
    if first != 0 {
        walk.ifd(first, true)?;
    }
    for img in &walk.images {
        check_image(img, bytes, walk.dng)?;
    }
    Ok(walk)
}

/// A depth-first walk over the IFD graph: every IFD's sub-IFDs and its next
/// IFD are its children. An IFD on the current path reached again is a
/// loop (rawler would follow it forever); one shared by two paths is only
/// counted against [`MAX_IFDS`].
pub(super) struct Walk<'a> {
    bytes: &'a [u8],
    order: Order,
    images: Vec<Image>,
    dng: bool,
    pub(super) visits: usize,
    path: Vec<u64>,
    /// Tags whose values are offsets of sub-IFDs.
    sub_tags: &'static [u16],
    /// Strip, tile and sub-IFD offsets and counts read so far.
    pub(super) listed: u64,
    /// A MakerNote's IFDs: their tags are the vendor's, so only the entries'
    /// extents (and `sub_tags`) are looked at, and rawler reads no next IFD
    /// after a MakerNote's.
    note: bool,
    /// The first Make and Model entries of the root chain (`None` inside:
    /// not ASCII) and whether the chain has a DNGVersion: what rawler picks
    /// the decoder by (`TiffReader::get_entry` reads the chain only).
    pub(super) make: Option<Option<String>>,
    pub(super) model: Option<Option<String>>,
    pub(super) dng_chain: bool,
    /// The MakerNote entries seen.
    notes: Vec<Entry>,
    /// Whether next-IFD offsets are followed (rawler reads only the first
    /// IFD of some structures).
    follow_next: bool,
    /// What rawler's reading of the IFDs walked (and of the structures it
    /// reads as IFDs from them) would allocate.
    pub(super) values: Values,
    /// The root chain's IFD offsets, in order.
    pub(super) chain: Vec<u64>,
}

/// Deeper than any camera's IFD nesting plus chain.
const MAX_DEPTH: usize = 64;

impl<'a> Walk<'a> {
    pub(super) fn new(bytes: &'a [u8], order: Order, sub_tags: &'static [u16], note: bool) -> Self {
        Walk {
            bytes,
            order,
            images: Vec::new(),
            dng: false,
            visits: 0,
            path: Vec::new(),
            sub_tags,
            listed: 0,
            note,
            make: None,
            model: None,
            dng_chain: false,
            notes: Vec::new(),
            follow_next: !note,
            values: Values::new(bytes.len()),
            chain: Vec::new(),
        }
    }

    /// Walk the IFD at `off`, one of the root chain if `chain`. Offset 0
    /// ends a chain of next-IFD pointers (and a root offset of 0 is refused
    /// by rawler itself), but a sub-IFD pointer of 0 is followed by rawler:
    /// to the file header, read as an IFD, so it is walked (and refused: the
    /// header is no IFD).
    pub(super) fn ifd(&mut self, off: u64, chain: bool) -> Result<(), ContainerError> {
        let (n, end) = self.enter(off)?;
        if chain {
            self.chain.push(off);
        }
        let mut img = Image::default();
        let mut children = Vec::new();
        for k in 0..n {
            let (tag, e) = self.entry(off, k)?;
            self.count_listed(tag, e.count)?;
            if self.sub_tags.contains(&tag) {
                let (bytes, order) = (self.bytes, self.order);
                children.extend(e.values(bytes, order).into_iter().map(|c| (c, false)));
                continue;
            }
            if !self.note {
                self.take(tag, e, chain, &mut img);
            }
        }
        // What rawler allocates for this IFD's entries (each lies inside the
        // file, but together they may not fit), and the structures
        // it reads as IFDs from its sub-IFD tags whatever their type (an
        // ICC profile, an UNDEFINED SubIFDs entry): read its way.
        let blob = Blob {
            bytes: self.bytes,
            order: self.order,
            base: 0,
            corr: 0,
        };
        let rawler_subs: &[u16] = if self.note {
            self.sub_tags
        } else {
            &RAWLER_SUB_TAGS
        };
        lenient::check_ifd(&blob, off as u32, rawler_subs, &mut self.values)?;
        if self.follow_next {
            // "Some TIFF writers skip the next ifd pointer": rawler reads a
            // missing one as 0 (formats/tiff/ifd.rs, line 192), and Canon's
            // CR3 metadata does skip it.
            let next = self.order.u32(self.bytes, end as usize).unwrap_or(0) as u64;
            if next != 0 {
                children.push((next, chain));
            }
        }
        if !self.note {
            self.images.push(img);
        }
        self.path.push(off);
        for (c, chain) in children {
            self.ifd(c, chain)?;
        }
        self.path.pop();
        Ok(())
    }

    /// The IFD at `off` checked before its entries are read (not reached
    /// twice, within the walk's bounds, its entry count and entries inside
    /// the file): its entry count and where its entries end.
    fn enter(&mut self, off: u64) -> Result<(usize, u64), ContainerError> {
        if self.path.contains(&off) {
            return Err(ContainerError::malformed(format!(
                "malformed TIFF structure: the IFD at byte {off} is reached twice (a loop in the IFD chain)"
            )));
        }
        self.visits += 1;
        if self.visits > MAX_IFDS || self.path.len() >= MAX_DEPTH {
            return Err(ContainerError::malformed(format!(
                "malformed TIFF structure: more than {MAX_IFDS} IFDs or {MAX_DEPTH} levels"
            )));
        }
        let (bytes, order) = (self.bytes, self.order);
        let len = bytes.len() as u64;
        let n = order
            .u16(bytes, off as usize)
            .filter(|_| off + 2 <= len)
            .ok_or_else(|| {
                ContainerError::malformed(format!("malformed TIFF structure: an IFD offset ({off}) lies beyond the file's {len} bytes"))
            })? as usize;
        if n > MAX_ENTRIES {
            return Err(ContainerError::malformed(format!(
                "malformed TIFF structure: an IFD at byte {off} claims {n} entries"
            )));
        }
        let end = off + 2 + 12 * n as u64;
        if end > len {
            return Err(ContainerError::malformed(format!(
                "malformed TIFF structure: the IFD at byte {off} ({n} entries) runs past the end of the file"
            )));
        }
        Ok((n, end))
    }

    /// Entry `k` of the IFD at `off` (inside the file: [`Walk::enter`]),
    /// its values checked to lie inside the file.
    fn entry(&self, off: u64, k: usize) -> Result<(u16, Entry), ContainerError> {
        let (bytes, order) = (self.bytes, self.order);
        let len = bytes.len() as u64;
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
                return Err(ContainerError::malformed(format!(
                    "malformed TIFF structure: tag {tag}'s {count} values at byte {v} run past the end of the file"
                )));
            }
            v as usize
        };
        Ok((tag, Entry { kind, count, at }))
    }

    /// Count a list the walk reads in full (strip and tile offsets and
    /// counts, sub-IFD pointers): bound the sum, or one IFD repeating a
    /// long list's tag thousands of times would be billions of reads.
    fn count_listed(&mut self, tag: u16, count: u64) -> Result<(), ContainerError> {
        let listed = !self.note
            && matches!(
                tag,
                TAG_STRIP_OFFSETS | TAG_STRIP_COUNTS | TAG_TILE_OFFSETS | TAG_TILE_COUNTS
            )
            || self.sub_tags.contains(&tag);
        if listed {
            self.listed = self.listed.saturating_add(count);
            if self.listed > MAX_LISTED {
                return Err(ContainerError::malformed(format!(
                    "malformed TIFF structure: more than {MAX_LISTED} strip, tile and IFD offsets"
                )));
            }
        }
        Ok(())
    }

    /// What an entry of a (non-MakerNote) IFD tells: the camera, DNG, a
    /// MakerNote to walk, or a field of the IFD's image.
    fn take(&mut self, tag: u16, e: Entry, chain: bool, img: &mut Image) {
        let (bytes, order) = (self.bytes, self.order);
        match tag {
            TAG_MAKE if chain && self.make.is_none() => self.make = Some(e.ascii(bytes)),
            TAG_MODEL if chain && self.model.is_none() => self.model = Some(e.ascii(bytes)),
            TAG_DNG_VERSION => {
                self.dng = true;
                self.dng_chain |= chain;
            }
            TAG_MAKERNOTE => {
                self.notes.push(e);
                return;
            }
            _ => {}
        }
        let one = || e.value(bytes, order, 0);
        match tag {
            TAG_WIDTH => img.width = one(),
            TAG_LENGTH => img.length = one(),
            TAG_BITS => img.bits = one(),
            TAG_SAMPLES => img.samples = one(),
            TAG_COMPRESSION => img.compression = one(),
            TAG_STRIP_OFFSETS => img.strips = e.values(bytes, order),
            TAG_STRIP_COUNTS => img.strip_counts = e.values(bytes, order),
            TAG_TILE_WIDTH => {
                img.tiled = true;
                img.tile_width = one();
            }
            TAG_TILE_LENGTH => {
                img.tiled = true;
                img.tile_length = one();
            }
            TAG_TILE_OFFSETS => img.tiles = e.values(bytes, order),
            TAG_TILE_COUNTS => img.tile_counts = e.values(bytes, order),
            _ => {}
        }
    }
}

fn check_image(img: &Image, bytes: &[u8], dng: bool) -> Result<(), ContainerError> {
    let len = bytes.len() as u64;
    let (Some(w), Some(h)) = (img.width, img.length) else {
        return Ok(());
    };
    if let Some(what) = too_many_pixels(w, h) {
        return Err(ContainerError::damaged(format!(
            "the file claims {what}: its header is damaged"
        )));
    }
    for (what, offsets, counts) in [
        ("strip", &img.strips, &img.strip_counts),
        ("tile", &img.tiles, &img.tile_counts),
    ] {
        for (i, (&o, &c)) in offsets.iter().zip(counts.iter()).enumerate() {
            if c > 0 && o < 8 {
                return Err(ContainerError::malformed(format!(
                    "malformed TIFF structure: {what} {i} starts at byte {o}, inside the file header"
                )));
            }
            if o.saturating_add(c) > len {
                return Err(ContainerError::truncated(format!(
                    "the image data is truncated: {what} {i} ({c} bytes at byte {o}) runs past the file's {len} bytes"
                )));
            }
        }
    }
    if !dng {
        return Ok(());
    }
    let spp = img.samples.unwrap_or(1);
    let bits = img.bits.unwrap_or(1);
    if img.tiled {
        let (tw, th) = (img.tile_width.unwrap_or(0), img.tile_length.unwrap_or(0));
        if tw == 0 || th == 0 {
            return Err(ContainerError::inconsistent(format!(
                "inconsistent DNG: a tiled {w} x {h} image with TileWidth {tw} and TileLength {th}"
            )));
        }
        // rawler decodes whole tiles: the padded area is what it allocates.
        let padded = (
            w.div_ceil(tw).saturating_mul(tw),
            h.div_ceil(th).saturating_mul(th),
        );
        if let Some(what) = too_many_pixels(padded.0, padded.1) {
            return Err(ContainerError::inconsistent(format!(
                "inconsistent DNG: tiles of {tw} x {th} make a {w} x {h} image {what}"
            )));
        }
    }
    let (what, offsets, counts) = if img.tiled {
        ("tile", &img.tiles, &img.tile_counts)
    } else {
        ("strip", &img.strips, &img.strip_counts)
    };
    match img.compression {
        // Uncompressed: the strips (or each tile) must hold the samples
        // BitsPerSample claims, to within a few bytes of padding: 12 bits
        // claimed over 14-bit data (1/6 more bytes) would decode to noise.
        Some(1) => check_uncompressed(img, counts, (w, h), (spp, bits)),
        // Lossless JPEG: each strip or tile must be a whole stream (rawler
        // decodes a cut one as zeros) and a tile's frame must be the tile.
        Some(7) => check_ljpeg(img, bytes, what, (offsets, counts), spp),
        _ => Ok(()),
    }
}

/// [`check_image`]'s check of an uncompressed DNG image: its strips (or
/// each tile) hold the samples BitsPerSample claims.
fn check_uncompressed(
    img: &Image,
    counts: &[u64],
    (w, h): (u64, u64),
    (spp, bits): (u64, u64),
) -> Result<(), ContainerError> {
    let slack = |need: u64| need / 64 + 16;
    let row = |width: u64| width.saturating_mul(spp).saturating_mul(bits).div_ceil(8);
    let held = |have: u64, pixels: u64| have as f64 * 8.0 / (pixels as f64 * spp as f64).max(1.0);
    if img.tiled {
        let (tw, th) = (img.tile_width.unwrap_or(0), img.tile_length.unwrap_or(0));
        let need = row(tw).saturating_mul(th);
        if let Some((i, &have)) = counts
            .iter()
            .enumerate()
            .find(|(_, &c)| c < need || c > need.saturating_add(slack(need)))
        {
            return Err(ContainerError::inconsistent(format!(
                    "inconsistent DNG: BitsPerSample says {bits} for tiles of {tw} x {th}, but tile {i} holds {:.1} bits per sample",
                    held(have, tw * th)
                )));
        }
    } else if !counts.is_empty() {
        let need = row(w).saturating_mul(h);
        let have: u64 = counts.iter().fold(0u64, |a, &c| a.saturating_add(c));
        if have < need || have > need.saturating_add(slack(need)) {
            return Err(ContainerError::inconsistent(format!(
                    "inconsistent DNG: BitsPerSample says {bits} for a {w} x {h} image, but its uncompressed strips hold {:.1} bits per sample",
                    held(have, w * h)
                )));
        }
    }
    Ok(())
}

/// [`check_image`]'s check of a lossless-JPEG DNG image: every strip or
/// tile a whole stream, a tile's frame the tile.
fn check_ljpeg(
    img: &Image,
    bytes: &[u8],
    what: &str,
    (offsets, counts): (&[u64], &[u64]),
    spp: u64,
) -> Result<(), ContainerError> {
    for (i, (&o, &c)) in offsets.iter().zip(counts.iter()).enumerate() {
        let data = &bytes[o as usize..(o + c) as usize];
        let frame = lossless_jpeg(data).map_err(|why| {
            ContainerError::damaged(format!(
                "damaged DNG: {what} {i}'s LJPEG data ({c} bytes at byte {o}) {why}"
            ))
        })?;
        if let (Some((wide, high, clrs)), true) = (frame, img.tiled) {
            let (tw, th) = (img.tile_width.unwrap_or(0), img.tile_length.unwrap_or(0));
            if wide.saturating_mul(clrs).saturating_mul(high)
                != tw.saturating_mul(th).saturating_mul(spp)
            {
                return Err(ContainerError::inconsistent(format!(
                        "inconsistent DNG: tile {i}'s LJPEG frame is {} x {high} samples, TileWidth x TileLength say {tw} x {th}",
                        wide * clrs
                    )));
            }
        }
    }
    Ok(())
}

/// The frame of an LJPEG-92 stream (a DNG's strip or tile): (samples per
/// line, lines, components) of its SOF3, checked to be whole: markers in
/// order up to the scan, then coded data that ends in a marker (EOI) inside
/// `data`. `Ok(None)` for a JPEG of another kind (a baseline preview: not
/// checked here); `Err` says what is wrong, as the end of a sentence about
/// the stream (the caller names it).
fn lossless_jpeg(data: &[u8]) -> Result<Option<(u64, u64, u64)>, ContainerError> {
    let cut_short = |why: &str| ContainerError::damaged(why.to_string());
    if data.get(..2) != Some(&[0xff, 0xd8][..]) {
        return Err(cut_short(
            "does not start with a JPEG start-of-image marker",
        ));
    }
    let cut = || cut_short("ends inside its JPEG header");
    let mut at = 2usize;
    let mut frame = None;
    loop {
        let (&b, &m) = (
            data.get(at).ok_or_else(cut)?,
            data.get(at + 1).ok_or_else(cut)?,
        );
        if b != 0xff {
            return Err(ContainerError::damaged(format!(
                "has no JPEG marker at byte {at} of its header"
            )));
        }
        if m == 0xff {
            at += 1; // fill byte
            continue;
        }
        at += 2;
        if (0xd0..=0xd7).contains(&m) || m == 0x01 {
            continue;
        }
        if m == 0xd9 {
            return Err(cut_short("ends (EOI) before its scan"));
        }
        let len = data
            .get(at..at + 2)
            .map(|l| u16::from_be_bytes([l[0], l[1]]) as usize)
            .ok_or_else(cut)?;
        let seg = data.get(at + 2..at + len.max(2)).ok_or_else(cut)?;
        match m {
            0xc3 => {
                let [_, hh, hl, wh, wl, n, ..] = *seg else {
                    return Err(cut_short("has a short frame header"));
                };
                let (high, wide) = (u16::from_be_bytes([hh, hl]), u16::from_be_bytes([wh, wl]));
                frame = Some((wide as u64, high as u64, n as u64));
            }
            0xc0..=0xcf if !matches!(m, 0xc4 | 0xc8 | 0xcc) => return Ok(None),
            0xda => {
                at += len.max(2);
                break;
            }
            _ => {}
        }
        at += len.max(2);
    }
    let Some(frame) = frame else {
        return Err(cut_short("has a scan but no lossless frame header (SOF3)"));
    };
    // The coded data ends at the first marker: 0xFF followed by neither a
    // stuffed zero, a restart marker nor a fill byte.
    let mut i = at;
    while let Some(p) = data
        .get(i..)
        .and_then(|d| d.iter().position(|&b| b == 0xff))
    {
        let k = i + p;
        match data.get(k + 1) {
            None => break,
            Some(0x00) | Some(0xd0..=0xd7) => i = k + 2,
            Some(0xff) => i = k + 1,
            Some(_) => return Ok(Some(frame)),
        }
    }
    Err(cut_short("is cut short: its coded data runs to the end of the bytes the file gives it, with no end-of-image marker"))
}

#[cfg(test)]
mod tests {
    use crate::container::check;
    use crate::container::testutil::tiff;

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
        let e = check(&tiff(&[(256, 3, 1, 4)], 8, &[]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("reached twice"), "{e}");
        // A SubIFD pointing back at the root.
        let e = check(&tiff(&[(330, 4, 1, 8)], 0, &[]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("reached twice"), "{e}");
        let e = check(&tiff(&[(256, 3, 1, 4)], 1 << 30, &[]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("beyond the file"), "{e}");
        // Values (10 LONGs) said to lie past the end.
        let e = check(&tiff(&[(273, 4, 10, 4000)], 0, &[]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("past the end"), "{e}");
        // An IFD claiming more entries than the file holds.
        let mut b = tiff(&[(256, 3, 1, 4)], 0, &[]);
        b[8] = 200;
        assert!(check(&b)
            .unwrap_err()
            .to_string()
            .contains("runs past the end"));
    }

    #[test]
    fn impossible_sizes_and_inconsistent_data_are_refused() {
        let mut huge = image(16, 4096, true);
        // ImageLength 0xFFFFFFFF as a LONG.
        huge[8 + 2 + 12 + 2..8 + 2 + 12 + 4].copy_from_slice(&4u16.to_le_bytes());
        huge[8 + 2 + 12 + 8..8 + 2 + 12 + 12].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(check(&huge).unwrap_err().to_string().contains("megapixels"));
        // BitsPerSample 8 over 16-bit data, and 16 over too little data.
        let e = check(&image(8, 4096, true)).unwrap_err().to_string();
        assert!(
            e.contains("BitsPerSample says 8") && e.contains("16.0 bits"),
            "{e}"
        );
        let mut short = image(16, 4096, true);
        let at = 8 + 2 + 12 * 6 + 8;
        short[at..at + 4].copy_from_slice(&8u32.to_le_bytes());
        assert!(check(&short)
            .unwrap_err()
            .to_string()
            .contains("BitsPerSample says 16"));
        // 14 over 16-bit data: 1/7 more bytes than the bits claimed, beyond
        // the few bytes of padding allowed (before issue 37: a quarter).
        let e = check(&image(14, 4096, true)).unwrap_err().to_string();
        assert!(e.contains("BitsPerSample says 14"), "{e}");
        assert_eq!(check(&image(16, 4096 + 16, true)), Ok(()));
        // Outside a DNG the bits are not checked (unpacked 12-bit NEFs).
        assert_eq!(check(&image(12, 4096, false)), Ok(()));
        // A strip at offset 0 reads the header as pixels; one past the end.
        let mut zero = image(16, 4096, true);
        let at = 8 + 2 + 12 * 4 + 8;
        zero[at..at + 4].copy_from_slice(&0u32.to_le_bytes());
        assert!(check(&zero)
            .unwrap_err()
            .to_string()
            .contains("inside the file header"));
        let mut past = image(16, 4096, false);
        past.truncate(past.len() - 4);
        assert!(check(&past).unwrap_err().to_string().contains("truncated"));
        // The cause, for callers that act on it (a file cut short can be
        // fetched again; one whose header lies cannot).
        use super::super::Cause;
        assert_eq!(check(&past).unwrap_err().cause, Cause::Truncated);
        assert_eq!(check(&zero).unwrap_err().cause, Cause::Malformed);
        assert_eq!(
            check(&image(8, 4096, true)).unwrap_err().cause,
            Cause::Inconsistent
        );
        assert_eq!(check(&huge).unwrap_err().cause, Cause::Damaged);
    }

    /// SOI, SOF3 (14 bits, 4 lines of 2 samples, 2 components), SOS, coded
    /// data with a stuffed 0xFF and a restart marker, EOI.
    fn ljpeg() -> Vec<u8> {
        let mut s = vec![0xff, 0xd8];
        s.extend([0xff, 0xc3, 0, 14, 14, 0, 4, 0, 2, 2, 0, 0x11, 0, 1, 0x11, 0]);
        s.extend([0xff, 0xda, 0, 10, 2, 0, 0, 1, 0, 1, 0, 0]);
        s.extend([0x12, 0xff, 0x00, 0x34, 0xff, 0xd0, 0x56, 0xff, 0xd9]);
        s
    }

    #[test]
    fn lossless_jpeg_streams_must_be_whole() {
        use super::lossless_jpeg;
        let s = ljpeg();
        assert_eq!(lossless_jpeg(&s), Ok(Some((2, 4, 2))));
        // Cut anywhere: in the header, in the coded data, inside the EOI.
        for cut in [1, 3, 10, 20, 30, s.len() - 3, s.len() - 1] {
            assert!(lossless_jpeg(&s[..cut]).is_err(), "cut at {cut}");
        }
        let e = lossless_jpeg(&s[..s.len() - 2]).unwrap_err().to_string();
        assert!(e.contains("cut short"), "{e}");
        // Fill bytes before the EOI, bytes after it: whole.
        let mut filled = s[..s.len() - 2].to_vec();
        filled.extend([0xff, 0xff, 0xd9, 7, 7]);
        assert_eq!(lossless_jpeg(&filled), Ok(Some((2, 4, 2))));
        // Not JPEG; a baseline JPEG (a preview) is not checked here.
        assert!(lossless_jpeg(b"\x00\x01\x02")
            .unwrap_err()
            .to_string()
            .contains("start-of-image"));
        assert_eq!(lossless_jpeg(&[0xff, 0xd8, 0xff, 0xc0, 0, 2]), Ok(None));
        let e = lossless_jpeg(&[0xff, 0xd8, 0xff, 0xd9])
            .unwrap_err()
            .to_string();
        assert!(e.contains("before its scan"), "{e}");
    }

    #[test]
    fn values_of_unknown_types_must_lie_inside_the_file() {
        // rawler reads an unknown type as bytes: 2^32 - 1 of them here.
        let e = check(&tiff(&[(256, 3, 1, 4), (700, 0, u32::MAX, 8)], 0, &[]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("past the end"), "{e}");
        let e = check(&tiff(&[(700, 99, 50, 8)], 0, &[]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("past the end"), "{e}");
        // Four bytes or fewer sit inline, as for any type.
        assert_eq!(check(&tiff(&[(700, 0, 4, 0)], 0, &[])), Ok(()));
    }

    #[test]
    fn the_offset_lists_read_are_bounded() {
        // `n` StripOffsets entries of 1100 LONGs each, all over the same
        // bytes after the IFD.
        let lists = |n: u32| {
            let values_at = 8 + 2 + 12 * n + 4;
            tiff(
                &vec![(273, 4, 1100, values_at); n as usize],
                0,
                &[0u8; 4400],
            )
        };
        // 4000 of them: 4.4 million values.
        let e = check(&lists(4000)).unwrap_err().to_string();
        assert!(
            e.contains("more than 4194304 strip, tile and IFD offsets"),
            "{e}"
        );
        assert_eq!(check(&lists(3)), Ok(()));
    }
}
