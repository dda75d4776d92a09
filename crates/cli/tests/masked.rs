//! Masked (optical-black) pixels from `pgrf synth --masked-columns` to
//! `pgrf enhance`: the strip is written as the DNG's MaskedAreas, read back
//! (and kept by `pgrf convert`) with its per-plane level, and an
//! uncalibrated enhance subtracts that level instead of the metadata's black,
//! which a capture's colour bias (ELD's per-capture offset draw) makes wrong.

mod common;
use common::{one_line_error, pgrf, s};

use pgrf_raw::{decode_file, write_dng, Cfa, DngOptions, LevelOverrides, RawFrame};
use std::path::{Path, PathBuf};

fn scratch(name: &str) -> PathBuf {
    common::scratch("masked", name)
}

const BLACK: f32 = 512.0;
const WHITE: u32 = 16383;
const W: usize = 256;
const H: usize = 192;

/// A clean frame with A7S2 metadata: its left half at black (no light),
/// its right half at 30 % of the range.
fn clean(path: &Path) {
    let lit = BLACK + 0.3 * (WHITE as f32 - BLACK);
    let mosaic = (0..W * H)
        .map(|i| if i % W < W / 2 { BLACK } else { lit } as u16)
        .collect();
    let mut f = RawFrame::from_mosaic(W, H, mosaic, Cfa::Rggb, [BLACK; 4], WHITE).unwrap();
    f.iso = Some(1600);
    f.exposure_s = Some(0.5);
    f.make = "Sony".into();
    f.model = "ILCE-7SM2".into();
    f.wb = Some([2.1, 1.0, 1.6]);
    write_dng(&f, path, &DngOptions::default()).unwrap();
}

fn synth(clean: &Path, out: &Path, masked: usize) {
    let r = pgrf(&[
        "synth",
        s(clean),
        "--profile",
        "sony-a7s2",
        "--iso",
        "1600",
        "--ratio",
        "100",
        "--seed",
        "51",
        "--masked-columns",
        &masked.to_string(),
        "-o",
        s(out),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
}

/// Mean and standard error of plane `p` (R, G1, B, G2 of RGGB) of the
/// frame's dark left half, DN.
fn dark_half(f: &RawFrame, p: usize) -> (f64, f64) {
    let (dr, dc) = Cfa::Rggb.offsets()[p];
    let v: Vec<f64> = (0..H / 2)
        .flat_map(|i| (0..W / 4).map(move |j| (2 * i + dr, 2 * j + dc)))
        .map(|(r, c)| f.mosaic[r * W + c] as f64)
        .collect();
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (var / n).sqrt())
}

/// The synthesised strip reads back as the DNG's MaskedAreas: 64 columns
/// beside the 256 visible ones, per-plane levels equal to the dark half's
/// mean within 5 standard errors of the two (both carry the capture's
/// offset), at least one plane more than 1 DN off the metadata's black (the
/// A7S2 ISO 1600 colour bias); `pgrf convert` keeps the strip bit for bit;
/// without the flag there is none.
#[test]
fn the_strip_reads_back_with_the_captures_offset() {
    let d = scratch("strip");
    let (c, cap) = (d.join("clean.dng"), d.join("cap.dng"));
    clean(&c);
    synth(&c, &cap, 64);
    let f = decode_file(&cap, &LevelOverrides::default()).unwrap();
    assert_eq!((f.width, f.height), (W, H));
    assert_eq!(f.sensor_size, (H, W + 64));
    let m = f.masked.clone().expect("masked pixels");
    assert_eq!(m.source, pgrf_raw::masked::MaskedSource::DngTag);
    assert_eq!(m.pixels, 64 * H / 4);
    let strip = m.strip.clone().expect("the strip kept");
    assert_eq!((strip.columns, strip.values.len()), (64, 64 * H));
    let mut off_black = 0.0f64;
    for p in 0..4 {
        let (mean, se) = dark_half(&f, p);
        // The strip's own standard error is about that of the half's
        // (the same noise over a third as many pixels: sqrt(3) x).
        let tol = 5.0 * se * (1.0 + 3f64.sqrt());
        let level = m.level[p] as f64;
        println!("plane {p}: masked {level:.3} DN, dark half {mean:.3} +- {se:.3}");
        assert!((level - mean).abs() < tol, "plane {p}: {level} vs {mean}");
        off_black = off_black.max((level - BLACK as f64).abs());
    }
    assert!(off_black > 1.0, "no offset drawn: {:?}", m.level);

    let copy = d.join("copy.dng");
    let r = pgrf(&["convert", s(&cap), "-o", s(&copy)]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let g = decode_file(&copy, &LevelOverrides::default()).unwrap();
    assert_eq!(g.mosaic, f.mosaic);
    assert_eq!(g.masked, f.masked);

    let plain = d.join("plain.dng");
    synth(&c, &plain, 0);
    let p = decode_file(&plain, &LevelOverrides::default()).unwrap();
    assert!(p.masked.is_none());
    assert_eq!(p.sensor_size, (H, W));
}

/// The median of the restoration's dark half above black, as a share of
/// the range, over all planes.
fn black_median(out: &Path) -> f64 {
    let f = decode_file(out, &LevelOverrides::default()).unwrap();
    let mut v: Vec<f64> = (8..H - 8)
        .flat_map(|r| (8..W / 2 - 8).map(move |c| (r, c)))
        .map(|(r, c)| {
            let p = f.cfa.plane_at(r, c);
            (f.mosaic[r * W + c] as f64 - f.black[p] as f64) / (f.white as f64 - f.black[p] as f64)
        })
        .collect();
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// `pgrf enhance` of the uncalibrated capture subtracts the masked level
/// and says so, and `--black` overrides it. With the metadata's black the
/// built-in SPC's black comes out +0.0138 of white above the reference's
/// (the capture's +2.5 DN offset, x100); with the masked level +0.0046:
/// what is left is the network's own (it reads its input clamped at black,
/// MODELS.md, issue 51), not the offset's. Asserted: below 0.006, and at
/// least 0.007 better.
#[test]
fn enhance_subtracts_the_masked_black() {
    let d = scratch("enhance");
    let (c, cap, plain) = (d.join("clean.dng"), d.join("cap.dng"), d.join("plain.dng"));
    clean(&c);
    synth(&c, &cap, 64);
    synth(&c, &plain, 0);
    let run = |input: &Path, out: &Path, extra: &[&str]| {
        let mut args = vec![
            "enhance",
            s(input),
            "--model",
            "builtin:spc",
            "--ratio",
            "100",
            "-o",
            s(out),
        ];
        args.extend_from_slice(extra);
        let r = pgrf(&args);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        String::from_utf8_lossy(&r.stderr).to_string()
    };
    let (a, b, o) = (d.join("a.dng"), d.join("b.dng"), d.join("o.dng"));
    let line = run(&cap, &a, &[]);
    assert!(
        line.contains("measured on the DNG's MaskedAreas (3072 px per plane"),
        "{line}"
    );
    let line = run(&plain, &b, &[]);
    assert!(!line.contains("MaskedAreas"), "{line}");
    let line = run(&cap, &o, &["--black", "512"]);
    assert!(!line.contains("MaskedAreas"), "{line}");
    let (masked, metadata) = (black_median(&a), black_median(&b));
    println!("black median: masked {masked:+.5}, metadata {metadata:+.5} of white");
    assert!(masked.abs() < 0.006, "masked black {masked}");
    assert!(metadata > masked.abs() + 0.007, "metadata black {metadata}");
}

#[test]
fn bad_masked_columns_are_refused_in_one_line() {
    let d = scratch("bad");
    let c = d.join("clean.dng");
    clean(&c);
    for (cols, out, want) in [
        ("3", "x.dng", "--masked-columns must be even"),
        ("2048", "x.dng", "at most 1024"),
        ("64", "x.fits", "a FITS output has no masked area"),
    ] {
        let r = pgrf(&[
            "synth",
            s(&c),
            "--profile",
            "sony-a7s2",
            "--masked-columns",
            cols,
            "-o",
            s(&d.join(out)),
        ]);
        let e = one_line_error(&r);
        assert!(e.contains(want), "{e}");
        assert!(!d.join(out).exists());
    }
}

/// Masked pixels far from the metadata's black (400 DN, more than 2 % of
/// the range) are more likely not dark than an offset: enhance keeps the
/// metadata's black and says why.
#[test]
fn a_masked_level_far_from_the_metadata_is_not_used() {
    let d = scratch("far");
    let (w, h, columns) = (64, 64, 16);
    let mosaic = vec![BLACK as u16 + 40; w * h];
    let mut f = RawFrame::from_mosaic(w, h, mosaic, Cfa::Rggb, [BLACK; 4], WHITE).unwrap();
    let strip = pgrf_raw::masked::MaskedStrip {
        columns,
        values: vec![BLACK as u16 + 400; columns * h],
    };
    f.masked = pgrf_raw::masked::Masked::of_strip(strip, h, Cfa::Rggb);
    let (input, out) = (d.join("far.dng"), d.join("out.dng"));
    write_dng(&f, &input, &DngOptions::default()).unwrap();
    let r = pgrf(&[
        "enhance",
        s(&input),
        "--model",
        "builtin:spc",
        "--ratio",
        "10",
        "--noise",
        "K=1.5,read=6",
        "-o",
        s(&out),
    ]);
    let line = String::from_utf8_lossy(&r.stderr).to_string();
    assert!(r.status.success(), "{line}");
    assert!(
        line.contains("black 512.00/512.00/512.00/512.00 DN from the metadata: the masked pixels (the DNG's MaskedAreas) read 912.00/912.00/912.00/912.00 DN, 400 DN away, not used"),
        "{line}"
    );
    let g = decode_file(&out, &LevelOverrides::default()).unwrap();
    assert_eq!(g.black, [BLACK; 4]);
}
