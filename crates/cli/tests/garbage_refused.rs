//! Files whose pixels would decode to garbage are refused in one line by
//! every command that reads them (issue 37, finding 4): a DNG tile cut
//! short by its TileByteCounts (it decoded to constant planes), a TileWidth
//! its LJPEG data does not have (all-zero planes), BitsPerSample 12 over the
//! 550D's 14-bit strip (0..4095 noise), and a FITS whose SATURATE lies below
//! its samples (it was silently ignored). Each file is made here from a
//! pgrf chart or the 550D asset, its entries found by walking the TIFF
//! structure.

mod common;
use common::{one_line_error, pgrf, s, scratch};
use std::path::{Path, PathBuf};

/// (entry offset, tag, type, count) of each entry of IFD0 (little-endian).
fn ifd0(b: &[u8]) -> Vec<(usize, u16, u16, u32)> {
    let u16_at = |i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
    let u32_at = |i: usize| u32::from_le_bytes(b[i..i + 4].try_into().unwrap());
    assert_eq!(&b[..4], b"II*\0");
    let off = u32_at(4) as usize;
    (0..u16_at(off) as usize)
        .map(|k| {
            let e = off + 2 + 12 * k;
            (e, u16_at(e), u16_at(e + 2), u32_at(e + 4))
        })
        .collect()
}

/// `bytes` with the (single, inline) value of `tag` in IFD0 set to `to`,
/// keeping the entry's type; written to `dir/name`.
fn patched(dir: &Path, name: &str, bytes: &[u8], tag: u16, to: u32) -> PathBuf {
    let (e, _, kind, count) = *ifd0(bytes)
        .iter()
        .find(|x| x.1 == tag)
        .unwrap_or_else(|| panic!("tag {tag} not in IFD0"));
    assert_eq!(count, 1, "tag {tag} has {count} values");
    let mut b = bytes.to_vec();
    match kind {
        3 => b[e + 8..e + 10].copy_from_slice(&(to as u16).to_le_bytes()),
        4 => b[e + 8..e + 12].copy_from_slice(&to.to_le_bytes()),
        k => panic!("tag {tag} of type {k}"),
    }
    let p = dir.join(name);
    std::fs::write(&p, b).unwrap();
    p
}

/// info, preview, convert and enhance each refuse `file` in one line
/// holding `needle`, writing nothing; with `extra` flags added they all
/// succeed instead (when given).
fn refused_by_all(dir: &Path, file: &Path, needle: &str) {
    for cmd in ["info", "preview", "convert", "enhance"] {
        let out = dir.join(format!("out_{cmd}"));
        let out = match cmd {
            "preview" => out.with_extension("png"),
            _ => out.with_extension("dng"),
        };
        let mut args = vec![cmd, s(file)];
        if cmd != "info" {
            args.extend_from_slice(&["-o", s(&out)]);
        }
        if cmd == "enhance" {
            args.extend_from_slice(&["--model", "builtin:spc", "--ratio", "20"]);
        }
        let e = one_line_error(&pgrf(&args));
        assert!(
            e.starts_with("pgrf: error: ") && e.contains(needle),
            "{cmd} {}: {e}",
            file.display()
        );
        assert!(!out.exists(), "{cmd} wrote {}", out.display());
    }
}

#[test]
fn dng_tiles_that_contradict_their_data_are_refused() {
    let d = scratch("garbage", "tiles");
    let chart = d.join("c.dng");
    common::chart(&chart, 256, 192);
    let b = std::fs::read(&chart).unwrap();
    // One 256 x 256 LJPEG tile (two components of 128 samples a line).
    let tags: Vec<u16> = ifd0(&b).iter().map(|e| e.1).collect();
    assert!(tags.contains(&322) && tags.contains(&325), "{tags:?}");

    let cut = patched(&d, "cut.dng", &b, 325, 100);
    refused_by_all(&d, &cut, "tile 0's LJPEG data (100 bytes at byte");
    refused_by_all(&d, &cut, "is cut short");
    let wide = patched(&d, "wide.dng", &b, 322, 65535);
    refused_by_all(
        &d,
        &wide,
        "tile 0's LJPEG frame is 256 x 256 samples, TileWidth x TileLength say 65535 x 256",
    );
    let zero = patched(&d, "zero.dng", &b, 322, 0);
    refused_by_all(&d, &zero, "TileWidth 0");
    // The chart itself goes through.
    let r = pgrf(&["info", s(&chart)]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn bits_per_sample_that_contradicts_the_strip_is_refused() {
    let asset = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/canon550d_colorchart.dng");
    let b = std::fs::read(&asset).unwrap();
    let d = scratch("garbage", "bits");
    // One uncompressed strip of 1888 x 1182 samples of 14 bits.
    let strip = ifd0(&b).iter().find(|e| e.1 == 279).map(|e| e.0).unwrap();
    let held = u32::from_le_bytes(b[strip + 8..strip + 12].try_into().unwrap());
    assert_eq!(held, 1888 * 1182 * 14 / 8);
    for (bits, says) in [(12u32, "14.0 bits"), (16, "14.0 bits"), (13, "14.0 bits")] {
        let f = patched(&d, &format!("bits{bits}.dng"), &b, 258, bits);
        refused_by_all(
            &d,
            &f,
            &format!("BitsPerSample says {bits} for a 1888 x 1182 image"),
        );
        refused_by_all(&d, &f, says);
    }
    let r = pgrf(&["info", s(&asset)]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    std::fs::remove_dir_all(&d).unwrap();
}

/// A FITS header card, 80 characters.
fn card(text: &str) -> Vec<u8> {
    format!("{text:<80}").into_bytes()
}

#[test]
fn a_fits_saturate_below_its_samples_is_refused_unless_white_is_given() {
    let d = scratch("garbage", "saturate");
    let chart = d.join("c.dng");
    common::chart(&chart, 256, 192);
    let fits = d.join("c.fits");
    let r = pgrf(&["convert", s(&chart), "-o", s(&fits)]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let mut b = std::fs::read(&fits).unwrap();
    // The chart's samples: its largest, and how many lie above 1000.
    let header_end = (0..b.len() / 80)
        .find(|&i| b[80 * i..80 * i + 8] == *b"END     ")
        .expect("an END card");
    let data_at = (80 * header_end).div_ceil(2880) * 2880;
    let samples: Vec<u16> = b[data_at..data_at + 2 * 256 * 192]
        .chunks(2)
        .map(|c| (i16::from_be_bytes([c[0], c[1]]) as i32 + 32768) as u16)
        .collect();
    let max = *samples.iter().max().unwrap();
    let above = samples.iter().filter(|&&x| x > 1000).count();
    assert!(max > 1000 && above > 0, "{max} {above}");
    // pgrf wrote SATURATE = 16383 (the chart's white); it becomes 1000.
    let sat = (0..header_end)
        .find(|&i| b[80 * i..80 * i + 9] == *b"SATURATE=")
        .expect("a SATURATE card");
    b[80 * sat..80 * sat + 80]
        .copy_from_slice(&card("SATURATE=                 1000 / saturation level"));
    let bad = d.join("sat.fits");
    std::fs::write(&bad, &b).unwrap();
    refused_by_all(
        &d,
        &bad,
        &format!(
            "SATURATE = 1000 lies below {above} of the {} samples (the largest is {max})",
            256 * 192
        ),
    );
    // --white settles it: every command runs (enhance writes samples up to
    // the raised white: 16 bits, not the file's 14).
    for cmd in ["info", "convert", "preview", "enhance"] {
        let ext = if cmd == "preview" { "png" } else { "dng" };
        let out = d.join(format!("ok_{cmd}.{ext}"));
        let mut args = vec![cmd, s(&bad), "--white", "65535"];
        if cmd != "info" {
            args.extend_from_slice(&["-o", s(&out)]);
        }
        if cmd == "enhance" {
            args.extend_from_slice(&["--model", "builtin:spc", "--ratio", "20"]);
            // A frame with no noise to estimate (a smooth synthetic ramp)
            // is restored at the quietest level the estimate resolves, and
            // says so (issue 53); --noise is then the user's to give.
            let r = pgrf(&args);
            let e = String::from_utf8_lossy(&r.stderr);
            assert!(r.status.success(), "{e}");
            assert!(
                e.contains("the smallest level the estimate resolves"),
                "{e}"
            );
            args.extend_from_slice(&["--noise", "K=1,read=4"]);
        }
        let r = pgrf(&args);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    }
    std::fs::remove_dir_all(&d).unwrap();
}
