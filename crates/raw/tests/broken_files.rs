//! Every broken or non-RAW input gives one clear line, never a panic.

mod common;

use pgrf_raw::{decode_file, read_headerless, Cfa, HeaderlessSpec, LevelOverrides};
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn assert_clean_error(path: &std::path::Path) -> String {
    let err = decode_file(path, &LevelOverrides::default())
        .err()
        .unwrap_or_else(|| panic!("{} decoded but should not", path.display()))
        .to_string();
    assert!(
        !err.contains('\n'),
        "multi-line error for {}: {err}",
        path.display()
    );
    assert!(
        err.contains(&*path.to_string_lossy()),
        "error does not name the file: {err}"
    );
    err
}

#[test]
#[cfg_attr(not(shared_data), ignore = "needs ../shared/data")]
fn every_broken_sample_is_a_one_line_error() {
    let data = common::data_dir();
    let mut n = 0;
    for entry in std::fs::read_dir(data.join("raw/broken")).unwrap() {
        assert_clean_error(&entry.unwrap().path());
        n += 1;
    }
    assert!(n >= 9, "expected the nine broken samples, found {n}");
}

#[test]
fn empty_random_directory_and_missing_inputs() {
    let dir = common::scratch("broken");
    let empty = dir.join("empty.dng");
    std::fs::write(&empty, b"").unwrap();
    assert!(assert_clean_error(&empty).contains("empty"));

    let mut rng = ChaCha8Rng::seed_from_u64(2024);
    for (i, len) in [1usize, 16, 4096, 200_000].into_iter().enumerate() {
        let mut bytes = vec![0u8; len];
        rng.fill_bytes(&mut bytes);
        let p = dir.join(format!("random{i}.cr2"));
        std::fs::write(&p, &bytes).unwrap();
        assert_clean_error(&p);
    }
    // TIFF magic followed by garbage reaches deeper into the parsers.
    let mut tiff = b"II*\x00\x08\x00\x00\x00".to_vec();
    let mut tail = vec![0u8; 10_000];
    rng.fill_bytes(&mut tail);
    tiff.extend(tail);
    let p = dir.join("garbage.dng");
    std::fs::write(&p, &tiff).unwrap();
    assert_clean_error(&p);

    assert!(assert_clean_error(&dir).contains("directory"));
    assert_clean_error(&dir.join("does-not-exist.arw"));
}

#[test]
#[cfg_attr(not(shared_data), ignore = "needs ../shared/data")]
fn linear_dng_is_refused_with_a_reason() {
    let data = common::data_dir();
    let err = assert_clean_error(&data.join("raw/canon6d_linear_lossy.dng"));
    assert!(err.contains("linear"), "{err}");
}

fn dslr_spec() -> HeaderlessSpec {
    HeaderlessSpec {
        width: 768,
        height: 512,
        bits: 14,
        cfa: Some(Cfa::Rggb),
        black: vec![600.0],
        white: Some(15520),
        big_endian: false,
    }
}

#[test]
#[cfg_attr(not(shared_data), ignore = "needs ../shared/data")]
fn headerless_dump_reads_and_validates() {
    let data = common::data_dir();
    let f = read_headerless(&data.join("raw/dslr_crop_768x512_rggb14.raw"), &dslr_spec()).unwrap();
    assert_eq!(
        (f.width, f.height, f.white, f.black),
        (768, 512, 15520, [600.0; 4])
    );
    // Known content: 14-bit samples, min 616, max 16383, mean 1693.17.
    assert_eq!(*f.mosaic.iter().min().unwrap(), 616);
    assert_eq!(*f.mosaic.iter().max().unwrap(), 16383);
    let mean = f.mosaic.iter().map(|&v| v as f64).sum::<f64>() / f.mosaic.len() as f64;
    assert!((mean - 1693.1713).abs() < 1e-3, "{mean}");

    // The bad-pixel twin differs in exactly the 400 injected pixels, some of
    // them stuck at 0xFFFF beyond the 14-bit range: kept, and counted.
    let bad = read_headerless(
        &data.join("raw/dslr_crop_768x512_rggb14_badpixels.raw"),
        &dslr_spec(),
    )
    .unwrap();
    let diff = f
        .mosaic
        .iter()
        .zip(&bad.mosaic)
        .filter(|(a, b)| a != b)
        .count();
    assert_eq!(diff, 400);
    assert!(pgrf_raw::headerless::samples_above_range(&bad) > 0);

    // Wrong geometry, truncation, wrong byte order: clear errors.
    let mut spec = dslr_spec();
    spec.width = 700;
    let e = read_headerless(&data.join("raw/dslr_crop_768x512_rggb14.raw"), &spec)
        .unwrap_err()
        .to_string();
    assert!(e.contains("bytes"), "{e}");
    let dir = common::scratch("headerless");
    let bytes = std::fs::read(data.join("raw/dslr_crop_768x512_rggb14.raw")).unwrap();
    std::fs::write(dir.join("cut.raw"), &bytes[..bytes.len() - 100]).unwrap();
    let e = read_headerless(&dir.join("cut.raw"), &dslr_spec())
        .unwrap_err()
        .to_string();
    assert!(e.contains("truncated"), "{e}");
    let mut be = dslr_spec();
    be.big_endian = true;
    let e = read_headerless(&data.join("raw/dslr_crop_768x512_rggb14.raw"), &be)
        .unwrap_err()
        .to_string();
    assert!(e.contains("byte order"), "{e}");
}
