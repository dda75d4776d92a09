//! Writing FITS: pgrf's own small encoder (fitsrs has none), BITPIX 16 with
//! BZERO 32768 for integer masters, BITPIX -32 for averaged ones, cards in
//! fixed format.

use super::*;

use crate::error::{RawError, Result};

/// Encode a u16 image as BITPIX 16 with BZERO 32768 (the unsigned-16
/// convention every astro camera driver uses), big-endian, in 2880-byte
/// blocks: the file a stacking program expects for an integer master.
///
/// `cards` follow the mandatory ones (SIMPLE, BITPIX, NAXIS, NAXIS1, NAXIS2,
/// BZERO, BSCALE); they may not repeat those nor each other.
pub fn encode_fits_u16(
    width: usize,
    height: usize,
    data: &[u16],
    cards: &[FitsCard],
) -> Result<Vec<u8>> {
    check_geometry(width, height, data.len())?;
    let fixed = [
        FitsCard::new(
            "BZERO",
            FitsValue::Int(32768),
            "offset data range to that of unsigned short",
        ),
        FitsCard::new("BSCALE", FitsValue::Int(1), "default scaling factor"),
    ];
    let mut out = header(16, width, height, &fixed, cards)?;
    out.reserve(padded(data.len() * 2));
    for &v in data {
        // stored = physical - BZERO, i.e. the sign bit flipped.
        out.extend_from_slice(&(v ^ 0x8000).to_be_bytes());
    }
    out.resize(padded(out.len()), 0);
    Ok(out)
}

/// Encode an f32 image as BITPIX -32 (IEEE big-endian), for averaged masters
/// whose fractional ADU would be lost in integers. NaN and infinities are
/// refused, as the reader refuses them.
pub fn encode_fits_f32(
    width: usize,
    height: usize,
    data: &[f32],
    cards: &[FitsCard],
) -> Result<Vec<u8>> {
    encode_fits_f32_history(width, height, data, cards, &[])
}

/// [`encode_fits_f32`] with HISTORY cards after the caller's, one per entry
/// of `history` (longer entries continue on further cards): how a reduced
/// light frame records the steps that made it, as FITS tools show them.
pub fn encode_fits_f32_history(
    width: usize,
    height: usize,
    data: &[f32],
    cards: &[FitsCard],
    history: &[String],
) -> Result<Vec<u8>> {
    check_geometry(width, height, data.len())?;
    let bad = data.iter().filter(|v| !v.is_finite()).count();
    if bad > 0 {
        return Err(RawError::NonFiniteMaster {
            bad,
            samples: data.len(),
        });
    }
    let mut out = header(-32, width, height, &[], cards)?;
    // Each HISTORY card replaces part of the END card's block: END is
    // written again after them.
    out.truncate(out.len() - padding_after_end(&out));
    for text in history {
        if !text.bytes().all(|b| (0x20..=0x7e).contains(&b)) {
            return Err(RawError::FitsCard {
                key: "HISTORY".into(),
                reason: "HISTORY text must be printable ASCII".into(),
            });
        }
        let chars: Vec<char> = text.chars().collect();
        for piece in chars.chunks(CARD - 8) {
            let piece: String = piece.iter().collect();
            out.extend_from_slice(format!("{:<80}", format!("HISTORY {piece}")).as_bytes());
        }
    }
    out.extend_from_slice(format!("{:<80}", "END").as_bytes());
    out.resize(padded(out.len()), b' ');
    out.reserve(padded(data.len() * 4));
    for &v in data {
        out.extend_from_slice(&v.to_be_bytes());
    }
    out.resize(padded(out.len()), 0);
    Ok(out)
}

// ---------------------------------------------------------------- reading

/// `len` rounded up to whole 2880-byte blocks.
fn padded(len: usize) -> usize {
    len.div_ceil(BLOCK) * BLOCK
}

/// How many bytes of `header` (whole cards, ending with END and padded
/// with spaces) lie from the start of its END card on: what to cut to
/// append cards before a new END.
fn padding_after_end(header: &[u8]) -> usize {
    let end = header
        .chunks(CARD)
        .rposition(|c| c.starts_with(b"END "))
        .expect("header() writes END");
    header.len() - end * CARD
}

fn check_geometry(width: usize, height: usize, len: usize) -> Result<()> {
    if width == 0 || height == 0 {
        return Err(RawError::FitsEmpty { width, height });
    }
    if width.checked_mul(height) != Some(len) {
        return Err(RawError::SampleCount {
            samples: len,
            width,
            height,
        });
    }
    Ok(())
}

/// Keywords the encoders write themselves or that are not plain value cards.
pub(super) fn reserved(key: &str) -> bool {
    matches!(
        key,
        "SIMPLE"
            | "BITPIX"
            | "NAXIS"
            | "EXTEND"
            | "BZERO"
            | "BSCALE"
            | "BLANK"
            | "END"
            | "COMMENT"
            | "HISTORY"
            | "CONTINUE"
            | "HIERARCH"
            | "XTENSION"
            | "PCOUNT"
            | "GCOUNT"
            | "GROUPS"
    ) || (key.starts_with("NAXIS") && key[5..].bytes().all(|b| b.is_ascii_digit()))
}

/// The header: mandatory cards, `fixed` (the encoder's own), the caller's
/// cards, END, padded with spaces to whole blocks.
fn header(
    bitpix: i32,
    width: usize,
    height: usize,
    fixed: &[FitsCard],
    cards: &[FitsCard],
) -> Result<Vec<u8>> {
    let mandatory = [
        FitsCard::new(
            "SIMPLE",
            FitsValue::Bool(true),
            "file does conform to FITS standard",
        ),
        FitsCard::new(
            "BITPIX",
            FitsValue::Int(i64::from(bitpix)),
            "number of bits per data pixel",
        ),
        FitsCard::new("NAXIS", FitsValue::Int(2), "number of data axes"),
        FitsCard::new(
            "NAXIS1",
            FitsValue::Int(width as i64),
            "length of data axis 1",
        ),
        FitsCard::new(
            "NAXIS2",
            FitsValue::Int(height as i64),
            "length of data axis 2",
        ),
    ];
    let mut seen = std::collections::HashSet::new();
    for c in cards {
        if reserved(&c.key) {
            return Err(RawError::FitsReservedKey { key: c.key.clone() });
        }
        if !seen.insert(c.key.as_str()) {
            return Err(RawError::FitsDuplicateKey { key: c.key.clone() });
        }
    }
    let mut out = Vec::with_capacity(BLOCK);
    for c in mandatory.iter().chain(fixed).chain(cards) {
        out.extend_from_slice(format_card(c)?.as_bytes());
    }
    out.extend_from_slice(format!("{:<80}", "END").as_bytes());
    out.resize(padded(out.len()), b' ');
    Ok(out)
}

/// One 80-character card in the FITS fixed format.
pub(super) fn format_card(c: &FitsCard) -> Result<String> {
    let bad = |reason: String| RawError::FitsCard {
        key: c.key.clone(),
        reason,
    };
    if c.key.is_empty()
        || c.key.len() > 8
        || !c
            .key
            .bytes()
            .all(|b| b.is_ascii_uppercase() || b.is_ascii_digit() || b == b'-' || b == b'_')
    {
        return Err(bad(
            "a keyword is 1 to 8 characters of A-Z, 0-9, '-' and '_'".into(),
        ));
    }
    let printable = |s: &str| s.bytes().all(|b| (0x20..=0x7e).contains(&b));
    let value = match &c.value {
        FitsValue::Int(v) => format!("{v:>20}"),
        FitsValue::Float(v) => {
            if !v.is_finite() {
                return Err(bad(format!("{v} is not a finite number")));
            }
            format!("{:>20}", format_real(*v))
        }
        FitsValue::Bool(b) => format!("{:>20}", if *b { "T" } else { "F" }),
        FitsValue::Str(s) => {
            if !printable(s) {
                return Err(bad("strings must be printable ASCII".into()));
            }
            // Quotes doubled; padded to 8 characters as the standard's
            // fixed format (closing quote in column 20 or later) asks.
            format!("'{:<8}'", s.replace('\'', "''"))
        }
    };
    if !printable(&c.comment) {
        return Err(bad("the comment must be printable ASCII".into()));
    }
    let mut card = format!("{:<8}= {value}", c.key);
    if !c.comment.is_empty() {
        card.push_str(" / ");
        card.push_str(&c.comment);
    }
    if card.len() > CARD {
        return Err(bad(format!(
            "{} characters do not fit in one 80-character card; shorten the value or comment",
            card.len()
        )));
    }
    Ok(format!("{card:<80}"))
}

/// The shortest text that reads back as `v`, in at most 20 characters, with
/// a decimal point so no reader takes it for an integer; past 20 characters
/// (only for extreme exponents) the precision is cut to fit, as astropy does.
pub(super) fn format_real(v: f64) -> String {
    let shortest = with_point(&format!("{v:?}").replace('e', "E"));
    if shortest.len() <= 20 {
        return shortest;
    }
    // Rounding up can overflow past f64::MAX: keep the first that reads back finite.
    (0..=16)
        .rev()
        .map(|p| with_point(&format!("{v:.p$E}")))
        .find(|s| s.len() <= 20 && s.parse::<f64>().is_ok_and(f64::is_finite))
        .unwrap_or_else(|| with_point(&format!("{v:.0E}")))
}

/// "1E20" -> "1.0E20"; strings with a '.' are returned unchanged.
pub(super) fn with_point(s: &str) -> String {
    if s.contains('.') {
        return s.to_string();
    }
    match s.find('E') {
        Some(i) => format!("{}.0{}", &s[..i], &s[i..]),
        None => format!("{s}.0"),
    }
}

/// `s` as a card's string value: printable ASCII only, at most 60
/// characters (what fits in a card beside its keyword and quotes).
pub fn card_text(s: &str) -> String {
    s.chars()
        .filter(|c| c.is_ascii_graphic() || *c == ' ')
        .take(60)
        .collect()
}
