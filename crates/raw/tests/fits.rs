//! FITS input/output of astro-camera frames: round trips through pgrf's
//! encoders, hand-made files of every BITPIX, the Bayer-phase convention,
//! hostile headers, and files written by astropy
//! (tests/reference/fits_astropy.py; no Python is needed here).

use pgrf_raw::fits::{
    encode_fits_f32, encode_fits_u16, is_fits, read_fits, FitsCard, FitsImage, FitsValue,
    KeywordError,
};
use pgrf_raw::{Cfa, RawError};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::{Path, PathBuf};

// ------------------------------------------------------------------ helpers

/// Records the largest single allocation made on the current thread, so a
/// test can show that a hostile header did not size a buffer.
struct LargestAllocation;

thread_local! {
    static LARGEST: Cell<usize> = const { Cell::new(0) };
}

fn note(size: usize) {
    let _ = LARGEST.try_with(|m| {
        if size > m.get() {
            m.set(size)
        }
    });
}

// A global allocator needs `unsafe impl`; it only forwards to the system's.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for LargestAllocation {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        System.alloc(layout)
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        System.alloc_zeroed(layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note(new_size);
        System.realloc(ptr, layout, new_size)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
}

#[global_allocator]
static ALLOCATOR: LargestAllocation = LargestAllocation;

fn name() -> PathBuf {
    PathBuf::from("frame.fits")
}

fn card(key: &str, value: FitsValue) -> FitsCard {
    FitsCard::new(key, value, "")
}

fn s(v: &str) -> FitsValue {
    FitsValue::Str(v.to_string())
}

/// A file written byte by byte, for what pgrf's encoders do not write
/// (BITPIX 8, 32, 64, -64, NaN, cubes, hostile headers). `cards` values are
/// written as given (quote strings yourself), right-justified to column 30.
fn raw_fits(cards: &[(&str, String)], data: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    for (k, v) in cards {
        out.extend_from_slice(format!("{:<80}", format!("{k:<8}= {v:>20}")).as_bytes());
    }
    out.extend_from_slice(format!("{:<80}", "END").as_bytes());
    out.resize(out.len().div_ceil(2880) * 2880, b' ');
    out.extend_from_slice(data);
    out.resize(out.len().div_ceil(2880) * 2880, 0);
    out
}

fn image_cards(bitpix: i32, axes: &[usize]) -> Vec<(&'static str, String)> {
    let mut c = vec![
        ("SIMPLE", "T".to_string()),
        ("BITPIX", bitpix.to_string()),
        ("NAXIS", axes.len().to_string()),
    ];
    for (i, n) in axes.iter().enumerate() {
        c.push((["NAXIS1", "NAXIS2", "NAXIS3"][i], n.to_string()));
    }
    c
}

fn error_line(bytes: &[u8]) -> String {
    let e = read_fits(&name(), bytes)
        .expect_err("read_fits accepted a file it should refuse")
        .to_string();
    assert!(!e.contains('\n'), "multi-line error: {e}");
    assert!(
        e.starts_with("frame.fits: "),
        "error does not name the file: {e}"
    );
    e
}

fn random_u16(rng: &mut ChaCha8Rng, n: usize) -> Vec<u16> {
    (0..n).map(|_| rng.random::<u16>()).collect()
}

/// A minimal u16 Bayer file with the given Bayer cards, to probe the phase.
fn bayer_file(height: usize, extra: &[FitsCard]) -> FitsImage {
    let width = 6;
    let data = vec![100u16; width * height];
    let bytes = encode_fits_u16(width, height, &data, extra).unwrap();
    read_fits(&name(), &bytes).unwrap()
}

// --------------------------------------------------------------- round trips

#[test]
fn mono_u16_round_trip_with_header_fields() {
    let mut rng = ChaCha8Rng::seed_from_u64(0xF175);
    let (w, h) = (37, 23);
    let mut data = random_u16(&mut rng, w * h);
    data[0] = 0;
    data[1] = 65535;
    let cards = [
        FitsCard::new("EXPTIME", FitsValue::Float(300.0), "[s] exposure"),
        card("EGAIN", FitsValue::Float(0.37)),
        card("GAIN", FitsValue::Int(120)),
        card("CCD-TEMP", FitsValue::Float(-10.3)),
        card("ISOSPEED", FitsValue::Int(1600)),
        card("INSTRUME", s("ZWO ASI2600MM Pro")),
        card("DATE-OBS", s("2024-02-03T01:02:03.250")),
        card("IMAGETYP", s("Dark Frame")),
    ];
    let bytes = encode_fits_u16(w, h, &data, &cards).unwrap();
    assert_eq!(bytes.len() % 2880, 0);
    assert!(is_fits(&bytes));
    let img = read_fits(&name(), &bytes).unwrap();
    assert_eq!((img.width, img.height), (w, h));
    assert_eq!(img.data, data);
    assert_eq!(img.bayer, None);
    assert_eq!(img.bitpix, 16);
    assert_eq!(img.white, 65535);
    assert_eq!(img.exposure_s, Some(300.0));
    assert_eq!(img.egain_e_per_adu, Some(0.37));
    assert_eq!(img.gain_setting, Some(120.0));
    assert_eq!(img.temperature_c, Some(-10.3));
    assert_eq!(img.iso, Some(1600));
    assert_eq!(img.instrument.as_deref(), Some("ZWO ASI2600MM Pro"));
    assert_eq!(img.date_obs.as_deref(), Some("2024-02-03T01:02:03.250"));
    assert_eq!(img.conversion, None);
}

#[test]
fn bayer_u16_round_trip_every_phase() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let (w, h) = (8, 6);
    for cfa in Cfa::ALL {
        let data = random_u16(&mut rng, w * h);
        let cards = [
            card("BAYERPAT", s(cfa.name())),
            card("XBAYROFF", FitsValue::Int(0)),
            card("YBAYROFF", FitsValue::Int(0)),
            card("ROWORDER", s("TOP-DOWN")),
            card("EXPOSURE", FitsValue::Float(2.5)),
            card("CCD_TEMP", FitsValue::Float(5.0)),
        ];
        let img = read_fits(&name(), &encode_fits_u16(w, h, &data, &cards).unwrap()).unwrap();
        assert_eq!(img.bayer, Some(cfa));
        assert_eq!(img.data, data);
        assert_eq!(
            img.exposure_s,
            Some(2.5),
            "EXPOSURE when there is no EXPTIME"
        );
        assert_eq!(
            img.temperature_c,
            Some(5.0),
            "CCD_TEMP when there is no CCD-TEMP"
        );
    }
}

#[test]
fn float_master_round_trip() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let (w, h) = (9, 7);
    // Averaged ADU with fractions: read back rounded.
    let data: Vec<f32> = (0..w * h)
        .map(|_| rng.random_range(0.0f32..65535.0))
        .collect();
    let img = read_fits(&name(), &encode_fits_f32(w, h, &data, &[]).unwrap()).unwrap();
    assert_eq!(img.bitpix, -32);
    let want: Vec<u16> = data.iter().map(|v| v.round() as u16).collect();
    assert_eq!(img.data, want);
    assert_eq!(
        img.conversion.as_deref(),
        Some("BITPIX -32 in 0..65535 rounded to integers")
    );
    // Normalised (Siril, PixInsight): scaled by 65535.
    let norm: Vec<f32> = (0..w * h).map(|i| i as f32 / (w * h - 1) as f32).collect();
    let img = read_fits(&name(), &encode_fits_f32(w, h, &norm, &[]).unwrap()).unwrap();
    let want: Vec<u16> = norm
        .iter()
        .map(|&v| (f64::from(v) * 65535.0).round() as u16)
        .collect();
    assert_eq!(img.data, want);
    assert_eq!((img.data[0], img.data[w * h - 1]), (0, 65535));
    assert_eq!(
        img.conversion.as_deref(),
        Some("BITPIX -32 in 0..1 scaled by 65535")
    );
}

#[test]
fn bitpix_8_reads_0_to_255() {
    let data: Vec<u8> = (0..=255u8).collect();
    let mut cards = image_cards(8, &[32, 8]);
    cards.push(("EXPTIME", "0.001".into()));
    let img = read_fits(&name(), &raw_fits(&cards, &data)).unwrap();
    assert_eq!(img.bitpix, 8);
    assert_eq!(img.white, 255);
    assert_eq!(img.data, (0..=255u16).collect::<Vec<_>>());
    assert_eq!(img.exposure_s, Some(0.001));
    assert_eq!(
        img.conversion.as_deref(),
        Some("BITPIX 8 widened to 16 bits")
    );
}

#[test]
fn bitpix_32_accepted_within_0_to_65535_and_refused_outside() {
    let values: Vec<i32> = vec![0, 1, 4095, 65535, 40000, 12, 7, 65000];
    let be = |v: &[i32]| v.iter().flat_map(|x| x.to_be_bytes()).collect::<Vec<u8>>();
    let img = read_fits(&name(), &raw_fits(&image_cards(32, &[4, 2]), &be(&values))).unwrap();
    assert_eq!(img.bitpix, 32);
    assert_eq!(img.white, 65535);
    let want: Vec<u16> = values.iter().map(|&v| v as u16).collect();
    assert_eq!(img.data, want);
    assert_eq!(
        img.conversion.as_deref(),
        Some("BITPIX 32 integers, all within 0..65535")
    );

    // BZERO applied: stored -100..., physical = stored + 100.
    let mut cards = image_cards(32, &[4, 2]);
    cards.push(("BZERO", "100".into()));
    let shifted: Vec<i32> = values.iter().map(|v| v - 100).collect();
    let img = read_fits(&name(), &raw_fits(&cards, &be(&shifted))).unwrap();
    assert_eq!(img.data, want);

    let mut out_of_range = values.clone();
    out_of_range[3] = 70000;
    out_of_range[5] = -3;
    let e = error_line(&raw_fits(&image_cards(32, &[4, 2]), &be(&out_of_range)));
    assert!(e.contains("BITPIX 32 values span -3..70000"), "{e}");
}

#[test]
fn bitpix_16_signed_without_bzero_and_bscale() {
    let be = |v: &[i16]| v.iter().flat_map(|x| x.to_be_bytes()).collect::<Vec<u8>>();
    // Signed 16-bit holding non-negative ADU (old 15-bit software): fine.
    let img = read_fits(
        &name(),
        &raw_fits(&image_cards(16, &[2, 2]), &be(&[0, 1, 32767, 5])),
    )
    .unwrap();
    assert_eq!(img.data, vec![0, 1, 32767, 5]);
    // The same bytes meant as unsigned but without BZERO: negatives refused.
    let e = error_line(&raw_fits(&image_cards(16, &[2, 2]), &be(&[0, -1, 5, 5])));
    assert!(e.contains("-1..5") && e.contains("BZERO = 32768"), "{e}");
    // BSCALE 2 doubles; BSCALE 0.5 makes fractions, refused.
    let mut cards = image_cards(16, &[2, 2]);
    cards.push(("BSCALE", "2".into()));
    let img = read_fits(&name(), &raw_fits(&cards, &be(&[0, 1, 2, 3]))).unwrap();
    assert_eq!(img.data, vec![0, 2, 4, 6]);
    let mut cards = image_cards(16, &[2, 2]);
    cards.push(("BSCALE", "0.5".into()));
    let e = error_line(&raw_fits(&cards, &be(&[0, 1, 2, 3])));
    assert!(
        e.contains("not integers") && e.contains("BSCALE = 0.5"),
        "{e}"
    );
    let mut cards = image_cards(16, &[2, 2]);
    cards.push(("BSCALE", "0".into()));
    assert!(error_line(&raw_fits(&cards, &be(&[0; 4]))).contains("BSCALE = 0"));
}

#[test]
fn bitpix_minus_64_and_nan_and_negative_floats() {
    let be64 = |v: &[f64]| v.iter().flat_map(|x| x.to_be_bytes()).collect::<Vec<u8>>();
    let img = read_fits(
        &name(),
        &raw_fits(&image_cards(-64, &[2, 2]), &be64(&[0.0, 0.25, 0.5, 1.0])),
    )
    .unwrap();
    assert_eq!(img.data, vec![0, 16384, 32768, 65535]);
    assert_eq!(
        img.conversion.as_deref(),
        Some("BITPIX -64 in 0..1 scaled by 65535")
    );

    // NaN and infinity in -32, counted.
    let mut bytes = encode_fits_f32(3, 2, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], &[]).unwrap();
    let data_at = 2880;
    bytes[data_at + 4..data_at + 8].copy_from_slice(&f32::NAN.to_be_bytes());
    bytes[data_at + 12..data_at + 16].copy_from_slice(&f32::NAN.to_be_bytes());
    bytes[data_at + 16..data_at + 20].copy_from_slice(&f32::NEG_INFINITY.to_be_bytes());
    let e = error_line(&bytes);
    assert!(e.contains("2 NaN and 1 infinite samples of 6"), "{e}");

    // Negative: a calibrated (bias-subtracted) frame, refused with the range.
    let bytes = encode_fits_f32(2, 2, &[-12.5, 3.0, 100.0, 7.0], &[]).unwrap();
    let e = error_line(&bytes);
    assert!(e.contains("-12.5..100") && e.contains("calibrated"), "{e}");
    let bytes = encode_fits_f32(2, 2, &[0.0, 3.0, 70000.0, 7.0], &[]).unwrap();
    assert!(error_line(&bytes).contains("0..70000"));
}

// ------------------------------------------------------------- Bayer phase

#[test]
fn xbayroff_one_turns_rggb_into_grbg() {
    let img = bayer_file(
        4,
        &[
            card("BAYERPAT", s("RGGB")),
            card("XBAYROFF", FitsValue::Int(1)),
        ],
    );
    assert_eq!(img.bayer, Some(Cfa::Grbg));
    let img = bayer_file(
        4,
        &[
            card("BAYERPAT", s("RGGB")),
            card("YBAYROFF", FitsValue::Int(1)),
        ],
    );
    assert_eq!(img.bayer, Some(Cfa::Gbrg));
    let img = bayer_file(
        4,
        &[
            card("BAYERPAT", s("RGGB")),
            card("XBAYROFF", FitsValue::Int(1)),
            card("YBAYROFF", FitsValue::Int(3)),
        ],
    );
    assert_eq!(img.bayer, Some(Cfa::Bggr));
}

#[test]
fn bottom_up_rggb_phase_follows_height_parity() {
    // BAYERPAT is the pattern seen top-down. Top-down row t of an RGGB
    // sensor is R G R G... when t is even, G B G B... when t is odd. In a
    // BOTTOM-UP file of height H, stored row s is top-down row H - 1 - s.
    //
    // H = 4: stored row 0 = top-down row 3 (odd: G B), stored row 1 = top-down
    // row 2 (even: R G), so the stored phase is G B / R G = GBRG, the
    // vertical flip of RGGB.
    let bu = card("ROWORDER", s("BOTTOM-UP"));
    let img = bayer_file(4, &[card("BAYERPAT", s("RGGB")), bu.clone()]);
    assert_eq!(img.bayer, Some(Cfa::Gbrg));
    // H = 5: stored row 0 = top-down row 4 (even: R G), stored row 1 = row 3
    // (odd: G B): RGGB, unchanged.
    let img = bayer_file(5, &[card("BAYERPAT", s("RGGB")), bu.clone()]);
    assert_eq!(img.bayer, Some(Cfa::Rggb));
    // With YBAYROFF = 1 as well (H = 4): pattern row of top-down row 3 is
    // (3 + 1) mod 2 = 0, so stored row 0 is R G again: RGGB.
    let img = bayer_file(
        4,
        &[
            card("BAYERPAT", s("RGGB")),
            card("YBAYROFF", FitsValue::Int(1)),
            bu.clone(),
        ],
    );
    assert_eq!(img.bayer, Some(Cfa::Rggb));
    // Lower case and padding are tolerated; rows are never flipped.
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let data = random_u16(&mut rng, 6 * 4);
    let bytes = encode_fits_u16(
        6,
        4,
        &data,
        &[
            card("BAYERPAT", s("bggr")),
            card("ROWORDER", s("bottom-up")),
        ],
    )
    .unwrap();
    let img = read_fits(&name(), &bytes).unwrap();
    assert_eq!(img.bayer, Some(Cfa::Grbg));
    assert_eq!(img.data, data);
}

#[test]
fn bayer_keywords_that_cannot_be_used_are_refused() {
    let try_read =
        |cards: &[FitsCard]| error_line(&encode_fits_u16(2, 2, &[1, 2, 3, 4], cards).unwrap());
    let e = try_read(&[card("BAYERPAT", s("TRUE"))]);
    assert!(
        e.contains("BAYERPAT = T") && e.contains("not its phase"),
        "{e}"
    );
    let e = try_read(&[card("BAYERPAT", FitsValue::Bool(true))]);
    assert!(e.contains("not its phase"), "{e}");
    let e = try_read(&[card("BAYERPAT", s("CMYG"))]);
    assert!(
        e.contains("BAYERPAT = 'CMYG' is not a 2x2 Bayer phase"),
        "{e}"
    );
    let e = try_read(&[card("BAYERPAT", s("RGGB")), card("ROWORDER", s("SIDEWAYS"))]);
    assert!(e.contains("ROWORDER = 'SIDEWAYS'"), "{e}");
    // A monochrome frame's row order matters too: what pgrf writes of it
    // states it.
    let e = try_read(&[card("ROWORDER", s("SIDEWAYS"))]);
    assert!(e.contains("ROWORDER = 'SIDEWAYS'"), "{e}");
    let e = try_read(&[
        card("BAYERPAT", s("RGGB")),
        card("XBAYROFF", FitsValue::Float(0.5)),
    ]);
    assert!(e.contains("XBAYROFF = 0.5 is not an integer"), "{e}");
    // No colour filter: absent, blank or F.
    for cards in [
        vec![],
        vec![card("BAYERPAT", s(""))],
        vec![card("BAYERPAT", FitsValue::Bool(false))],
    ] {
        let bytes = encode_fits_u16(2, 2, &[1, 2, 3, 4], &cards).unwrap();
        assert_eq!(read_fits(&name(), &bytes).unwrap().bayer, None);
    }
}

// -------------------------------------------------------- metadata and white

#[test]
fn unusable_metadata_is_named() {
    let try_read =
        |cards: &[FitsCard]| error_line(&encode_fits_u16(2, 2, &[1, 2, 3, 4], cards).unwrap());
    assert!(try_read(&[card("EXPTIME", s("long"))]).contains("EXPTIME = 'long' is not a number"));
    assert!(
        try_read(&[card("EXPTIME", FitsValue::Float(-1.0))]).contains("EXPTIME = -1 s is negative")
    );
    assert!(try_read(&[card("EGAIN", FitsValue::Int(0))]).contains("EGAIN = 0"));
    assert!(try_read(&[card("CCD-TEMP", FitsValue::Float(-400.0))]).contains("CCD-TEMP = -400"));
    assert!(try_read(&[card("ISOSPEED", FitsValue::Int(-5))]).contains("ISOSPEED = -5"));
    assert!(
        try_read(&[card("INSTRUME", FitsValue::Int(5))]).contains("INSTRUME = 5 is not a string")
    );
    // The card at fault is there for a caller, not only in the words.
    let bytes = encode_fits_u16(2, 2, &[1, 2, 3, 4], &[card("EXPTIME", s("long"))]).unwrap();
    match read_fits(&name(), &bytes) {
        Err(RawError::FitsKeyword { error, .. }) => {
            assert_eq!(error.key(), "EXPTIME");
            assert!(matches!(error, KeywordError::NotANumber { .. }), "{error}");
        }
        other => panic!("expected a keyword error, got {other:?}"),
    }
    // Numbers written as strings by some programs are read.
    let bytes = encode_fits_u16(2, 2, &[1, 2, 3, 4], &[card("EXPTIME", s("30"))]).unwrap();
    assert_eq!(read_fits(&name(), &bytes).unwrap().exposure_s, Some(30.0));
}

#[test]
fn saturate_and_datamax_lower_the_white_level() {
    let read = |cards: &[FitsCard]| {
        read_fits(
            &name(),
            &encode_fits_u16(2, 2, &[0, 100, 4000, 4095], cards).unwrap(),
        )
        .unwrap()
        .white
    };
    assert_eq!(read(&[]), 65535);
    assert_eq!(read(&[card("SATURATE", FitsValue::Int(4095))]), 4095);
    assert_eq!(read(&[card("DATAMAX", FitsValue::Float(16383.0))]), 16383);
    assert_eq!(
        read(&[
            card("SATURATE", FitsValue::Int(4095)),
            card("DATAMAX", FitsValue::Int(16383))
        ]),
        4095
    );
    // Not a full scale: a fraction, or not smaller.
    assert_eq!(read(&[card("SATURATE", FitsValue::Float(4095.5))]), 65535);
    assert_eq!(read(&[card("SATURATE", FitsValue::Int(70000))]), 65535);
}

/// A saturation level two of the four samples exceed contradicts the data:
/// the image reads with full scale and says why, and a frame decoded for use
/// is refused in one line unless --white gives the level (issue 37).
#[test]
fn a_saturation_level_below_the_samples_is_refused_unless_white_is_given() {
    use pgrf_raw::{decode_bytes, LevelOverrides};
    for key in ["SATURATE", "DATAMAX"] {
        let bytes = encode_fits_u16(
            2,
            2,
            &[0, 100, 4000, 4095],
            &[card(key, FitsValue::Int(1000))],
        )
        .unwrap();
        let img = read_fits(&name(), &bytes).unwrap();
        assert_eq!(img.white, 65535);
        let why = img.white_conflict.expect("a conflict");
        assert!(
            why.contains(&format!(
                "{key} = 1000 lies below 2 of the 4 samples (the largest is 4095)"
            )),
            "{why}"
        );
        let e = decode_bytes(&name(), &bytes, &LevelOverrides::default())
            .unwrap_err()
            .to_string();
        assert!(
            !e.contains('\n') && e.contains("contradicts the data"),
            "{e}"
        );
        for white in [1000, 65535] {
            let f = decode_bytes(
                &name(),
                &bytes,
                &LevelOverrides {
                    white: Some(white),
                    ..Default::default()
                },
            )
            .unwrap();
            assert_eq!(f.white, white);
        }
    }
    // At or above the largest sample it is the white level, no conflict.
    let bytes = encode_fits_u16(
        2,
        2,
        &[0, 100, 4000, 4095],
        &[card("SATURATE", FitsValue::Int(4095))],
    )
    .unwrap();
    assert_eq!(read_fits(&name(), &bytes).unwrap().white_conflict, None);
}

// --------------------------------------------------------- hostile headers

#[test]
fn truncated_data_is_one_error_line() {
    let data = vec![1000u16; 64 * 48];
    let bytes = encode_fits_u16(64, 48, &data, &[]).unwrap();
    let cut = &bytes[..2880 + 64 * 48 * 2 / 2];
    let e = error_line(cut);
    assert_eq!(
        e,
        "frame.fits: cannot decode: truncated: the image needs 6144 bytes after the header, \
         the file has 3072"
    );
    // Cut inside the header.
    let e = error_line(&bytes[..1000]);
    assert!(e.contains("truncated"), "{e}");
    let e = error_line(&bytes[..480]);
    assert!(e.contains("no END card"), "{e}");
}

#[test]
fn huge_header_claim_errors_without_allocating() {
    let cards = image_cards(16, &[65536, 65536]);
    let bytes = raw_fits(&cards, &[0u8; 100]);
    LARGEST.with(|m| m.set(0));
    let e = error_line(&bytes);
    let largest = LARGEST.with(Cell::get);
    // Past 600 MP: refused from the header alone (issue 37).
    assert!(
        e.contains("a 65536 x 65536 image (4295 megapixels), more than any camera makes"),
        "{e}"
    );
    assert!(largest < 1 << 20, "largest allocation {largest} bytes");
    // Within 600 MP, a header whose data are missing is truncated.
    let bytes = raw_fits(&image_cards(16, &[20000, 20000]), &[0u8; 100]);
    let e = error_line(&bytes);
    assert!(
        e.contains(
            "truncated: the image needs 800000000 bytes after the header, the file has 2880"
        ),
        "{e}"
    );

    for (axes, key) in [([70000usize, 4], "NAXIS1 = 70000"), ([4, 1], "NAXIS2 = 1")] {
        let e = error_line(&raw_fits(&image_cards(16, &axes), &[0u8; 16]));
        assert!(e.contains(key) && e.contains("outside 2..=65536"), "{e}");
    }
    // Lengths whose product overflows 64 bits, caught before fitsrs multiplies them.
    let e = error_line(&raw_fits(&image_cards(16, &[1 << 32, 1 << 32]), &[0u8; 16]));
    assert!(
        e.contains("NAXIS1 = 4294967296 is outside 2..=65536"),
        "{e}"
    );
    let e = error_line(&raw_fits(&image_cards(16, &[4, 4, 1 << 62]), &[0u8; 16]));
    assert!(e.contains("NAXIS3 = 4611686018427387904: a cube"), "{e}");
    let e = error_line(&raw_fits(&image_cards(12, &[2, 2]), &[0u8; 8]));
    assert!(e.contains("BITPIX = 12 is not a FITS sample type"), "{e}");
    let mut cards = image_cards(16, &[2, 2]);
    cards.remove(3);
    let e = error_line(&raw_fits(&cards, &[0u8; 8]));
    assert!(e.contains("NAXIS1 is missing"), "{e}");
}

#[test]
fn cubes_one_plane_read_three_planes_refused() {
    let data: Vec<u8> = (0..2 * 2 * 3 * 2).map(|i| i as u8).collect();
    let e = error_line(&raw_fits(&image_cards(16, &[2, 2, 3]), &data));
    assert_eq!(
        e,
        "frame.fits: unsupported: already demosaiced colour (3 planes); pgrf needs the sensor's \
         raw frame"
    );
    let e = error_line(&raw_fits(&image_cards(16, &[2, 2, 5]), &data));
    assert!(e.contains("NAXIS3 = 5"), "{e}");
    let img = read_fits(&name(), &raw_fits(&image_cards(16, &[2, 2, 1]), &data[..8])).unwrap();
    assert_eq!(img.data, vec![1, 515, 1029, 1543]);
    let e = error_line(&raw_fits(&image_cards(16, &[8]), &data));
    assert!(e.contains("NAXIS = 1"), "{e}");
}

#[test]
fn not_fits_and_mutated_files_give_one_line() {
    assert!(error_line(&[]).contains("empty"));
    assert!(error_line(b"II*\0 not a fits file at all").contains("not a FITS file"));
    assert!(!is_fits(b"SIMPLE  =                    F"));
    // Seeded mutations of a valid Bayer file: truncations, byte flips and
    // zeroed windows. Each read is a value or one error line, never a panic.
    let mut rng = ChaCha8Rng::seed_from_u64(0x5EED);
    let data = random_u16(&mut rng, 16 * 12);
    let good = encode_fits_u16(
        16,
        12,
        &data,
        &[
            card("BAYERPAT", s("RGGB")),
            card("EXPTIME", FitsValue::Float(1.5)),
            card("ROWORDER", s("TOP-DOWN")),
        ],
    )
    .unwrap();
    let mut refused = 0;
    for i in 0..400 {
        let mut b = good.clone();
        match i % 3 {
            0 => b.truncate(rng.random_range(0..b.len())),
            1 => {
                for _ in 0..rng.random_range(1..8) {
                    let at = rng.random_range(0..2880);
                    b[at] = rng.random();
                }
            }
            _ => {
                let at = rng.random_range(0..2880 - 80);
                let len = rng.random_range(1..80);
                b[at..at + len].fill(0);
            }
        }
        if read_fits(&name(), &b).is_err() {
            error_line(&b);
            refused += 1;
        }
    }
    assert!(refused > 100, "only {refused} of 400 mutations refused");
}

// ----------------------------------------------------------------- writing

#[test]
fn encoders_refuse_what_they_cannot_write() {
    let e = |r: pgrf_raw::Result<Vec<u8>>| r.unwrap_err().to_string();
    assert!(e(encode_fits_u16(3, 3, &[0; 8], &[])).contains("do not make a 3x3 image"));
    assert!(e(encode_fits_u16(0, 3, &[], &[])).contains("at least 1"));
    assert!(e(encode_fits_u16(
        2,
        2,
        &[0; 4],
        &[card("BZERO", FitsValue::Int(0))]
    ))
    .contains("writes this keyword itself"));
    assert!(e(encode_fits_u16(
        2,
        2,
        &[0; 4],
        &[card("NAXIS3", FitsValue::Int(1))]
    ))
    .contains("writes this keyword itself"));
    assert!(e(encode_fits_u16(
        2,
        2,
        &[0; 4],
        &[
            card("EXPTIME", FitsValue::Int(1)),
            card("EXPTIME", FitsValue::Int(2))
        ]
    ))
    .contains("given twice"));
    assert!(e(encode_fits_u16(
        2,
        2,
        &[0; 4],
        &[card("exptime", FitsValue::Int(1))]
    ))
    .contains("1 to 8 characters"));
    assert!(e(encode_fits_f32(2, 1, &[0.5, f32::NAN], &[])).contains("1 of 2 samples are NaN"));
}

#[test]
fn written_header_is_standard_and_padded() {
    let bytes = encode_fits_u16(
        3,
        2,
        &[0, 1, 2, 65533, 65534, 65535],
        &[FitsCard::new(
            "EXPTIME",
            FitsValue::Float(30.0),
            "[s] exposure time",
        )],
    )
    .unwrap();
    let header = std::str::from_utf8(&bytes[..2880]).unwrap();
    let cards: Vec<&str> = (0..36).map(|i| &header[i * 80..i * 80 + 80]).collect();
    assert_eq!(
        cards[0].trim_end(),
        "SIMPLE  =                    T / file does conform to FITS standard"
    );
    assert_eq!(&cards[1][..30], "BITPIX  =                   16");
    assert_eq!(&cards[2][..30], "NAXIS   =                    2");
    assert_eq!(&cards[3][..30], "NAXIS1  =                    3");
    assert_eq!(&cards[4][..30], "NAXIS2  =                    2");
    assert_eq!(&cards[5][..30], "BZERO   =                32768");
    assert_eq!(&cards[6][..30], "BSCALE  =                    1");
    assert_eq!(
        cards[7].trim_end(),
        "EXPTIME =                 30.0 / [s] exposure time"
    );
    assert_eq!(cards[8].trim_end(), "END");
    assert!(cards[9..].iter().all(|c| c.trim().is_empty()));
    // Data: big-endian, stored = value - 32768, zero-padded to the block.
    assert_eq!(bytes.len(), 5760);
    assert_eq!(&bytes[2880..2886], &[0x80, 0x00, 0x80, 0x01, 0x80, 0x02]);
    assert_eq!(&bytes[2886..2892], &[0x7F, 0xFD, 0x7F, 0xFE, 0x7F, 0xFF]);
    assert!(bytes[2892..].iter().all(|&b| b == 0));
}

// ------------------------------------------------ astropy interoperability

fn fixture(file: &str) -> Vec<u8> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/fits")
        .join(file);
    std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Values printed by `python3 tests/reference/fits_astropy.py write`.
#[test]
fn reads_files_written_by_astropy() {
    let img = read_fits(
        Path::new("astropy_rggb_u16.fits"),
        &fixture("astropy_rggb_u16.fits"),
    )
    .unwrap();
    assert_eq!((img.width, img.height, img.bitpix), (6, 4, 16));
    #[rustfmt::skip]
    let want: Vec<u16> = vec![
        0, 2731, 5462, 8193, 10924, 13655,
        16386, 19117, 21848, 24579, 27310, 30041,
        32772, 35503, 38234, 40965, 43696, 46427,
        49158, 51889, 54620, 57351, 60082, 65535,
    ];
    assert_eq!(img.data, want);
    assert_eq!(img.bayer, Some(Cfa::Rggb));
    assert_eq!(img.exposure_s, Some(30.0));
    assert_eq!(img.egain_e_per_adu, Some(0.8));
    assert_eq!(img.gain_setting, Some(120.0));
    assert_eq!(img.temperature_c, Some(-10.0));
    assert_eq!(img.instrument.as_deref(), Some("ZWO ASI294MC Pro"));
    assert_eq!(img.date_obs.as_deref(), Some("2024-03-01T21:15:00.000"));
    assert_eq!((img.white, img.conversion.as_deref()), (65535, None));

    let img = read_fits(
        Path::new("astropy_mono_f32.fits"),
        &fixture("astropy_mono_f32.fits"),
    )
    .unwrap();
    assert_eq!((img.width, img.height, img.bitpix), (6, 4, -32));
    #[rustfmt::skip]
    let want: Vec<u16> = vec![
        2621, 5243, 7864, 10486, 13107, 15728,
        18350, 20971, 23593, 26214, 28835, 31457,
        34078, 36700, 39321, 41942, 44564, 47185,
        49807, 52428, 55049, 57671, 60292, 62914,
    ];
    assert_eq!(img.data, want);
    assert_eq!(img.bayer, None);
    assert_eq!(img.exposure_s, Some(5.0));
    assert_eq!(
        img.conversion.as_deref(),
        Some("BITPIX -32 in 0..1 scaled by 65535")
    );

    let bytes = fixture("astropy_fpack_rice.fits");
    assert!(is_fits(&bytes));
    let e = read_fits(Path::new("astropy_fpack_rice.fits"), &bytes)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("astropy_fpack_rice.fits: unsupported: tile-compressed (fpack)")
            && e.contains("funpack")
            && !e.contains('\n'),
        "{e}"
    );
}

/// Writes the files `tests/reference/fits_astropy.py check DIR` reads with
/// astropy, when PGRF_FITS_ASTROPY_DIR names DIR; does nothing otherwise.
#[test]
fn pgrf_files_for_astropy() {
    let Some(dir) = std::env::var_os("PGRF_FITS_ASTROPY_DIR") else {
        return;
    };
    let dir = PathBuf::from(dir);
    std::fs::create_dir_all(&dir).unwrap();
    let (w, h) = (7usize, 5usize);
    let data: Vec<u16> = (0..w * h).map(|i| ((i * 9973) % 65536) as u16).collect();
    let cards = [
        FitsCard::new("EXPTIME", FitsValue::Float(120.5), "[s] exposure time"),
        card("EGAIN", FitsValue::Float(1.25)),
        card("GAIN", FitsValue::Int(100)),
        card("CCD-TEMP", FitsValue::Float(-15.5)),
        card("ISOSPEED", FitsValue::Int(800)),
        card("INSTRUME", s("QHY 'test' 268C")),
        card("BAYERPAT", s("GRBG")),
        card("XBAYROFF", FitsValue::Int(1)),
        card("YBAYROFF", FitsValue::Int(0)),
        card("ROWORDER", s("TOP-DOWN")),
        card("DATE-OBS", s("2026-01-02T03:04:05.500")),
    ];
    let bytes = encode_fits_u16(w, h, &data, &cards).unwrap();
    std::fs::write(dir.join("pgrf_bayer_u16.fits"), &bytes).unwrap();
    // And pgrf reads its own file back the same.
    let img = read_fits(&name(), &bytes).unwrap();
    assert_eq!(img.data, data);
    assert_eq!(img.bayer, Some(Cfa::Rggb)); // GRBG shifted by one column

    let (w, h) = (5usize, 3usize);
    let master: Vec<f32> = (0..w * h).map(|i| 1000.125 + 0.25 * i as f32).collect();
    let cards = [
        card("IMAGETYP", s("Master Dark")),
        card("NCOMBINE", FitsValue::Int(16)),
    ];
    let bytes = encode_fits_f32(w, h, &master, &cards).unwrap();
    std::fs::write(dir.join("pgrf_master_f32.fits"), &bytes).unwrap();
}

/// XBINNING / YBINNING are read (an absent axis is 1), refused outside
/// 1..64 in one line, kept by the decoded frame and written back by every
/// FITS pgrf writes of it (issue 39: reduce refuses lights binned unlike
/// the masters).
#[test]
fn binning_is_read_kept_and_written_back() {
    use pgrf_raw::{decode_bytes, encode_fits_frame, LevelOverrides};
    let with = |cards: &[FitsCard]| encode_fits_u16(2, 2, &[1, 2, 3, 4], cards).unwrap();
    let read = |cards: &[FitsCard]| read_fits(&name(), &with(cards)).unwrap().binning;
    assert_eq!(read(&[]), None);
    let two = [
        card("XBINNING", FitsValue::Int(2)),
        card("YBINNING", FitsValue::Int(2)),
    ];
    assert_eq!(read(&two), Some((2, 2)));
    assert_eq!(read(&[card("XBINNING", FitsValue::Int(3))]), Some((3, 1)));
    assert_eq!(read(&[card("YBINNING", FitsValue::Int(4))]), Some((1, 4)));
    for bad in [0, 65, -2] {
        let e = error_line(&with(&[card("XBINNING", FitsValue::Int(bad))]));
        assert!(
            e.contains(&format!("XBINNING = {bad} is not a binning factor")),
            "{e}"
        );
    }
    let frame = decode_bytes(&name(), &with(&two), &LevelOverrides::default()).unwrap();
    assert_eq!(frame.fits.as_ref().unwrap().binning, Some((2, 2)));
    let again = read_fits(&name(), &encode_fits_frame(&frame).unwrap()).unwrap();
    assert_eq!(again.binning, Some((2, 2)));
}
