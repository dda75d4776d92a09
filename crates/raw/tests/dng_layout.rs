//! The layout of the LJPEG-92 tiles pgrf writes, read back from the files
//! themselves: the rule that makes LibRaw decode them exactly
//! (`pgrf_raw::tile_width`), held here so that CI without rawpy still
//! guards it. tests/reference/dng_width_sweep.py checks the same sizes
//! against LibRaw itself (0.22.2 through rawpy 0.28: 61 of 238 sizes wrong
//! before this layout, none after).
//!
//! `libraw_places` follows the column and row stepping of LibRaw's
//! `lossless_dng_load_raw` / `lossless_dng_decode_tile` (case 0xc3): each
//! sample of a tile's JPEG rows must land on the pixel the writer took it
//! from.

use pgrf_raw::{decode_bytes, encode_dng, tile_width, Cfa, DngOptions, RawFrame, DNG_TILE};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;

/// Values of one IFD entry (SHORT or LONG), little-endian files only (what
/// pgrf writes on every platform it builds for).
fn entry(b: &[u8], ifd: usize, tag: u16) -> Option<Vec<u32>> {
    let u16_at = |o: usize| u16::from_le_bytes([b[o], b[o + 1]]);
    let u32_at = |o: usize| u32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]);
    let n = u16_at(ifd) as usize;
    (0..n).find_map(|i| {
        let at = ifd + 2 + 12 * i;
        if u16_at(at) != tag {
            return None;
        }
        let (kind, count) = (u16_at(at + 2), u32_at(at + 4) as usize);
        let size = if kind == 3 { 2 } else { 4 };
        let base = if size * count <= 4 {
            at + 8
        } else {
            u32_at(at + 8) as usize
        };
        Some(
            (0..count)
                .map(|k| match kind {
                    3 => u16_at(base + 2 * k) as u32,
                    _ => u32_at(base + 4 * k),
                })
                .collect(),
        )
    })
}

/// (samples per line, lines, components) of an LJPEG-92 stream's SOF3.
fn sof3(jpeg: &[u8]) -> (usize, usize, usize) {
    assert_eq!(&jpeg[..2], &[0xff, 0xd8], "no SOI");
    let mut at = 2;
    loop {
        assert_eq!(jpeg[at], 0xff, "marker expected at {at}");
        let marker = jpeg[at + 1];
        let len = u16::from_be_bytes([jpeg[at + 2], jpeg[at + 3]]) as usize;
        if marker == 0xc3 {
            let s = &jpeg[at + 4..];
            let high = u16::from_be_bytes([s[1], s[2]]) as usize;
            let wide = u16::from_be_bytes([s[3], s[4]]) as usize;
            return (wide, high, s[5] as usize);
        }
        at += 2 + len;
    }
}

/// Where LibRaw puts each sample of one tile: (row, column) in the image
/// for the `jrow`-th JPEG row's samples in order, `None` for the padding it
/// drops. `clrs` and `wide` are the SOF's, `filters` whether the image has
/// a CFA (LibRaw's jwide: wide x clrs when it has, or when it is one colour).
fn libraw_places(
    raw_width: usize,
    tile_width: usize,
    (trow, tcol): (usize, usize),
    (wide, high, clrs): (usize, usize, usize),
) -> Vec<Vec<(usize, usize)>> {
    let jwide = wide * clrs;
    // `tiff_samples == 1 && jh.clrs > 1 && jh.clrs * jwide == raw_width`:
    // twice (clrs times) the samples a JPEG row holds.
    let per_row = if clrs > 1 && clrs * jwide == raw_width {
        jwide * clrs
    } else {
        jwide
    };
    let (mut row, mut col) = (0, 0);
    let mut out = Vec::new();
    for _ in 0..high {
        let mut r = Vec::new();
        for _ in 0..per_row {
            r.push((trow + row, tcol + col));
            col += 1;
            if col >= tile_width || col >= raw_width {
                row += 1;
                col = 0;
            }
        }
        out.push(r);
    }
    out
}

fn frame(width: usize, height: usize, mono: bool, seed: u64) -> RawFrame {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mosaic = (0..width * height)
        .map(|_| rng.random_range(600..16000u16))
        .collect();
    let mut f = RawFrame::from_mosaic(width, height, mosaic, Cfa::Rggb, [512.0; 4], 16383).unwrap();
    f.mono = mono;
    f
}

/// Every size of the reference sweep (and then some) gets a layout LibRaw
/// reads sample for sample, and pgrf reads back exactly.
#[test]
fn every_tile_layout_is_one_libraw_reads_exactly() {
    let widths = [
        16, 18, 22, 30, 32, 34, 64, 100, 128, 200, 240, 254, 255, 256, 257, 258, 300, 384, 496,
        510, 511, 512, 513, 514, 528, 640, 768, 1000, 1024, 1536, 1888,
    ];
    let mut checked = 0;
    for (k, &w) in widths.iter().enumerate() {
        for &(h, mono) in &[(22usize, false), (257, false), (40, true)] {
            let f = frame(w, h, mono, 37 + k as u64);
            let bytes = encode_dng(&f, &DngOptions::default()).unwrap();
            let ifd0 = u32::from_le_bytes(bytes[4..8].try_into().unwrap()) as usize;
            let get = |tag| entry(&bytes, ifd0, tag).unwrap();
            let (tw, th) = (get(322)[0] as usize, get(323)[0] as usize);
            assert_eq!((get(256)[0] as usize, get(257)[0] as usize), (w, h));
            assert_eq!(tw, tile_width(w));
            assert_eq!(th, DNG_TILE);
            // The rule itself: a multiple of 16, never wider than the frame,
            // never exactly half of it.
            assert!(tw % 16 == 0 && tw <= w && 2 * tw != w, "{w}: tile {tw}");
            let (offsets, counts) = (get(324), get(325));
            let (cols, rows) = (w.div_ceil(tw), h.div_ceil(th));
            assert_eq!(offsets.len(), cols * rows);
            for (i, (&o, &n)) in offsets.iter().zip(&counts).enumerate() {
                let jpeg = &bytes[o as usize..(o + n) as usize];
                assert_eq!(&jpeg[jpeg.len() - 2..], &[0xff, 0xd9], "tile {i}: no EOI");
                let sof = sof3(jpeg);
                let clrs = if mono { 1 } else { 2 };
                assert_eq!(sof, (tw / clrs, th, clrs), "{w}x{h} tile {i}");
                let (trow, tcol) = (i / cols * th, i % cols * tw);
                for (jrow, places) in libraw_places(w, tw, (trow, tcol), sof).iter().enumerate() {
                    // The writer's sample k of JPEG row jrow is the tile's
                    // pixel (jrow, k); LibRaw keeps what lies in the image.
                    assert_eq!(places.len(), tw, "{w}x{h} tile {i}: row length");
                    for (k, &(r, c)) in places.iter().enumerate() {
                        let (wr, wc) = (trow + jrow, tcol + k);
                        if wr < h && wc < w {
                            assert_eq!((r, c), (wr, wc), "{w}x{h} tile {i} row {jrow}");
                        }
                    }
                }
            }
            let back = decode_bytes(Path::new("t.dng"), &bytes, &Default::default()).unwrap();
            assert!(back.mosaic == f.mosaic, "{w}x{h}: pgrf's decode differs");
            checked += 1;
        }
    }
    assert_eq!(checked, 3 * widths.len());
}

/// The model of LibRaw's loop finds the layouts that failed before: tiles of
/// 256 in a frame of 512 (the `clrs * jwide == raw_width` case) and in a
/// frame narrower than the tile.
#[test]
fn the_libraw_model_sees_the_old_layouts_fail() {
    let wrong = |w: usize, tw: usize| {
        libraw_places(w, tw, (0, 0), (tw / 2, 4, 2))
            .iter()
            .enumerate()
            .flat_map(|(jrow, p)| {
                p.iter()
                    .take(tw)
                    .enumerate()
                    .map(move |(k, &rc)| (jrow, k, rc))
            })
            .filter(|&(jrow, k, (r, c))| k < w && (r, c) != (jrow, k))
            .count()
    };
    assert_eq!(wrong(512, 256), 3 * 256); // every row after the first
    assert_eq!(wrong(200, 256), 3 * 200);
    assert_eq!(wrong(512, 512), 0);
    assert_eq!(wrong(200, 192), 0);
    assert_eq!(
        (tile_width(512), tile_width(200), tile_width(8)),
        (512, 192, 16)
    );
    assert_eq!(
        (tile_width(256), tile_width(6000), tile_width(1024)),
        (256, 256, 256)
    );
}
