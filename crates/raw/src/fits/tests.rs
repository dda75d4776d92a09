//! The FITS reader and writer against hand-made files.

use super::read::*;
use super::write::*;
use super::*;

#[test]
fn cards_are_in_fixed_format() {
    let card = |k: &str, v: FitsValue, c: &str| format_card(&FitsCard::new(k, v, c)).unwrap();
    let c = card("EXPTIME", FitsValue::Float(30.0), "seconds");
    assert_eq!(c.len(), 80);
    assert_eq!(&c[..30], "EXPTIME =                 30.0");
    assert_eq!(c[30..].trim_end(), " / seconds");
    let c = card("XBAYROFF", FitsValue::Int(-1), "");
    assert_eq!(c.trim_end(), "XBAYROFF=                   -1");
    let c = card("SIMPLE", FitsValue::Bool(true), "");
    assert_eq!(&c[29..30], "T");
    let c = card("INSTRUME", FitsValue::Str("ZWO 'ASI' 294".into()), "");
    assert_eq!(c.trim_end(), "INSTRUME= 'ZWO ''ASI'' 294'");
    let c = card("BAYERPAT", FitsValue::Str("RGGB".into()), "");
    assert_eq!(c.trim_end(), "BAYERPAT= 'RGGB    '");
}

#[test]
fn bad_cards_are_refused() {
    let try_card = |k: &str, v: FitsValue, c: &str| format_card(&FitsCard::new(k, v, c));
    assert!(try_card("exptime", FitsValue::Int(1), "").is_err());
    assert!(try_card("TOOLONGKEY", FitsValue::Int(1), "").is_err());
    assert!(try_card("A B", FitsValue::Int(1), "").is_err());
    assert!(try_card("", FitsValue::Int(1), "").is_err());
    assert!(try_card("X", FitsValue::Float(f64::NAN), "").is_err());
    assert!(try_card("X", FitsValue::Float(f64::INFINITY), "").is_err());
    assert!(try_card("X", FitsValue::Str("é".into()), "").is_err());
    assert!(try_card("X", FitsValue::Str("a\tb".into()), "").is_err());
    assert!(try_card("X", FitsValue::Str("x".repeat(69)), "").is_err());
    assert!(try_card("X", FitsValue::Str("x".repeat(68)), "").is_ok());
    assert!(try_card("X", FitsValue::Int(1), &"c".repeat(60)).is_err());
    assert!(try_card("DATE-OBS", FitsValue::Int(1), "").is_ok());
    assert!(try_card("CCD_TEMP", FitsValue::Int(1), "").is_ok());
}

#[test]
fn reals_read_back_exactly_and_fit() {
    for v in [
        0.0,
        -0.0,
        1.0,
        0.1,
        -12.5,
        1e-7,
        1e20,
        123456.789,
        6.02214076e23,
        -1.5e-300,
        f64::MAX,
        f64::MIN_POSITIVE,
        1.2345678901234567e-300,
    ] {
        let s = format_real(v);
        assert!(s.len() <= 20, "{s}");
        assert!(s.contains('.'), "{s}");
        let back: f64 = s.parse().unwrap();
        if with_point(&format!("{v:?}")).len() <= 20 {
            assert_eq!(back.to_bits(), v.to_bits(), "{s}");
        } else {
            assert!(((back - v) / v).abs() < 1e-12, "{s}");
        }
    }
}

#[test]
fn reserved_keywords() {
    for k in [
        "SIMPLE", "NAXIS", "NAXIS3", "BZERO", "END", "COMMENT", "BLANK",
    ] {
        assert!(reserved(k), "{k}");
    }
    for k in ["NAXISX", "EXPTIME", "BAYERPAT"] {
        assert!(!reserved(k), "{k}");
    }
}

#[test]
fn stored_phase_follows_siril() {
    // Siril's adjust_Bayer_pattern_offset: odd XBAYROFF RGGB->GRBG,
    // BGGR->GBRG, GBRG->BGGR, GRBG->RGGB; odd YBAYROFF RGGB->GBRG,
    // BGGR->GRBG, GBRG->RGGB, GRBG->BGGR.
    let x = [
        (Cfa::Rggb, Cfa::Grbg),
        (Cfa::Bggr, Cfa::Gbrg),
        (Cfa::Gbrg, Cfa::Bggr),
        (Cfa::Grbg, Cfa::Rggb),
    ];
    for (from, to) in x {
        assert_eq!(stored_phase(from, 1, 0, false, 100), to);
        assert_eq!(stored_phase(from, -1, 0, false, 100), to);
        assert_eq!(stored_phase(from, 2, 0, false, 100), from);
    }
    let y = [
        (Cfa::Rggb, Cfa::Gbrg),
        (Cfa::Bggr, Cfa::Grbg),
        (Cfa::Gbrg, Cfa::Rggb),
        (Cfa::Grbg, Cfa::Bggr),
    ];
    for (from, to) in y {
        assert_eq!(stored_phase(from, 0, 1, false, 100), to);
        // Siril's adjust_Bayer_pattern_orientation: BOTTOM-UP with an
        // even height flips the 2x2 rows, with an odd height it does not.
        assert_eq!(stored_phase(from, 0, 0, true, 100), to);
        assert_eq!(stored_phase(from, 0, 0, true, 101), from);
        // Flip then odd YBAYROFF: two row swaps cancel.
        assert_eq!(stored_phase(from, 0, 1, true, 100), from);
    }
}

#[test]
fn value_field_reads_strings_and_numbers() {
    let card = |s: &str| format!("{s:<80}").into_bytes();
    assert_eq!(
        value_field(&card("BITPIX  =                   16 / x")),
        Some("16")
    );
    assert_eq!(
        value_field(&card("XTENSION= 'BINTABLE'  / x")),
        Some("'BINTABLE'")
    );
    assert_eq!(
        value_field(&card("A       = 'it''s / here' / c")),
        Some("'it''s / here'")
    );
    assert_eq!(value_field(&card("COMMENT hello")), None);
    assert_eq!(value_field(&card("A       =    / c")), None);
    assert!(is_fits(&card("SIMPLE  =                    T / conforms")));
    assert!(!is_fits(&card("SIMPLE  =                    F")));
    assert!(!is_fits(b"SIMPLE  = T"));
}
