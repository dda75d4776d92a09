//! FITS frames as [`RawFrame`]s: what [`crate::decode_file`] makes of an
//! astronomy camera's FITS file, and frames and calibration masters written
//! back as FITS for the astrophotographer's tools (Siril, PixInsight,
//! DeepSkyStacker read them).
//!
//! A FITS file records no black level: a cooled camera's pedestal is in the
//! data and a bias stack measures it, so frames come in with black 0 (give
//! `--black` where a known pedestal matters). Rows stay in the file's stored
//! order, and the Bayer phase is that of stored pixel (0, 0) ([`crate::fits`]
//! works it out from BAYERPAT, ROWORDER and the offsets). What pgrf writes
//! keeps those rows and says which order they are in
//! ([`RawFrame::row_order`]: a FITS file's own, BOTTOM-UP when it stated
//! none; TOP-DOWN for frames from a camera RAW), with BAYERPAT stated so
//! that a reader applying the convention finds the same phase, so a round
//! trip keeps rows and phase and a master lines up with its lights.

use crate::error::{RawError, Result};
use crate::fits::{
    encode_fits_f32, encode_fits_u16, read_fits, FitsCard, FitsHeader, FitsValue, RowOrder,
};
use crate::frame::{LevelOverrides, RawFrame};
use pgrf_core::write_atomic;
use std::path::Path;

/// The frame of FITS file `bytes` (`path` names it in errors), with
/// `overrides` applied to its levels.
pub(crate) fn frame_from_fits(
    path: &Path,
    bytes: &[u8],
    overrides: &LevelOverrides,
) -> Result<RawFrame> {
    let img = read_fits(path, bytes)?;
    if let (Some(why), None) = (&img.white_conflict, overrides.white) {
        return Err(RawError::decode(path, why));
    }
    let mut frame = match img.bayer {
        Some(cfa) => {
            RawFrame::from_mosaic(img.width, img.height, img.data, cfa, [0.0; 4], img.white)
        }
        None => RawFrame::from_mono(img.width, img.height, img.data, 0.0, img.white),
    }
    .map_err(|e| RawError::decode(path, e.to_string()))?;
    frame.exposure_s = img.exposure_s;
    frame.iso = img.iso;
    frame.temperature_c = img.temperature_c;
    frame.model = img.instrument.unwrap_or_default();
    frame.fits = Some(FitsHeader {
        bitpix: img.bitpix,
        egain_e_per_adu: img.egain_e_per_adu,
        gain_setting: img.gain_setting,
        date_obs: img.date_obs,
        image_type: img.image_type,
        filter: img.filter,
        object: img.object,
        row_order: img.row_order,
        binning: img.binning,
        conversion: img.conversion,
    });
    frame.apply_overrides(overrides)?;
    Ok(frame)
}

/// The saturation keyword: the white level in the ADU of integer samples.
/// Masters, whose samples are normalised to 0-1, carry none.
const SATURATE: &str = "SATURATE";

impl RawFrame {
    /// The order this frame's rows are in: a FITS frame's stored order
    /// (its ROWORDER, BOTTOM-UP by the FITS convention when it has none);
    /// TOP-DOWN for a camera RAW's or a synthesised frame, whose first row
    /// is the sensor's top row.
    pub fn row_order(&self) -> RowOrder {
        match &self.fits {
            Some(h) => h.row_order.unwrap_or(RowOrder::BottomUp),
            None => RowOrder::TopDown,
        }
    }
}

/// The header cards every FITS file pgrf writes of `frame` carries: its
/// row order ([`RawFrame::row_order`]: rows are written as the frame holds
/// them), exposure, ISO, temperature, camera and (for a colour sensor) its
/// Bayer pattern with no offsets. BAYERPAT names the pattern as seen
/// top-down, so a BOTTOM-UP frame of even height, whose stored row 0 is
/// the top-down row H - 1, states its stored phase shifted by one row
/// ([`crate::fits`]'s convention, which reads it back to `frame.cfa`).
fn frame_cards(frame: &RawFrame) -> Vec<FitsCard> {
    let card = FitsCard::new;
    let rows = frame.row_order();
    let mut cards = vec![card(
        "ROWORDER",
        FitsValue::Str(rows.keyword().into()),
        match rows {
            RowOrder::TopDown => "first row stored is the top row",
            RowOrder::BottomUp => "first row stored is the bottom row",
        },
    )];
    if !frame.mono {
        let pattern =
            crate::fits::stored_phase(frame.cfa, 0, 0, rows == RowOrder::BottomUp, frame.height);
        cards.push(card(
            "BAYERPAT",
            FitsValue::Str(pattern.name().into()),
            "colour filter of the top-left 2x2 cell, seen top-down",
        ));
        cards.push(card(
            "XBAYROFF",
            FitsValue::Int(0),
            "Bayer pattern x offset",
        ));
        cards.push(card(
            "YBAYROFF",
            FitsValue::Int(0),
            "Bayer pattern y offset",
        ));
    }
    cards.push(card(
        SATURATE,
        FitsValue::Int(frame.white as i64),
        "saturation level [ADU]",
    ));
    if let Some(t) = frame.exposure_s.filter(|t| t.is_finite()) {
        cards.push(card("EXPTIME", FitsValue::Float(t), "exposure time [s]"));
    }
    if let Some(iso) = frame.iso {
        cards.push(card("ISOSPEED", FitsValue::Int(iso as i64), "ISO speed"));
    }
    if let Some(t) = frame.temperature_c.filter(|t| t.is_finite()) {
        cards.push(card(
            "CCD-TEMP",
            FitsValue::Float(t as f64),
            "sensor temperature [C]",
        ));
    }
    let camera = instrument(frame);
    if !camera.is_empty() {
        cards.push(card("INSTRUME", FitsValue::Str(camera), "camera"));
    }
    cards.extend(observation_cards(frame));
    if let Some(g) = frame.fits.as_ref().and_then(|h| h.egain_e_per_adu) {
        cards.push(card("EGAIN", FitsValue::Float(g), "electrons per ADU"));
    }
    if let Some((x, y)) = frame.fits.as_ref().and_then(|h| h.binning) {
        cards.push(card(
            "XBINNING",
            FitsValue::Int(x.into()),
            "binning, columns",
        ));
        cards.push(card("YBINNING", FitsValue::Int(y.into()), "binning, rows"));
    }
    cards.push(card(
        "CREATOR",
        FitsValue::Str(format!("pgrf {}", env!("CARGO_PKG_VERSION"))),
        "",
    ));
    cards
}

/// DATE-OBS, OBJECT and FILTER of a frame read from FITS, as read: what
/// an astronomer's tools sort and stack by, kept in every FITS file
/// written of the frame (its conversion, its reduction).
fn observation_cards(frame: &RawFrame) -> Vec<FitsCard> {
    let Some(h) = frame.fits.as_ref() else {
        return Vec::new();
    };
    [
        ("DATE-OBS", &h.date_obs, "start of the exposure"),
        ("OBJECT", &h.object, "what was observed"),
        ("FILTER", &h.filter, "filter"),
    ]
    .into_iter()
    .filter_map(|(key, value, comment)| {
        let text = crate::fits::card_text(value.as_deref()?);
        (!text.is_empty()).then(|| FitsCard::new(key, FitsValue::Str(text), comment))
    })
    .collect()
}

/// The unit of the 32-bit float samples pgrf writes (DN / 65535), as
/// astropy's CCDData reads BUNIT: `CCDData.read` gives the samples this
/// unit and converts them to ADU exactly.
const FLOAT_BUNIT: &str = "65535 adu";

/// The BUNIT card of normalised float samples.
fn float_unit_card() -> FitsCard {
    FitsCard::new(
        "BUNIT",
        FitsValue::Str(FLOAT_BUNIT.into()),
        "samples are ADU / 65535",
    )
}

/// The camera as INSTRUME states it: make and model, printable ASCII, at
/// most 60 characters (empty when the file names no camera).
fn instrument(frame: &RawFrame) -> String {
    let camera = [frame.make.as_str(), frame.model.as_str()]
        .into_iter()
        .filter(|s| !s.is_empty())
        .collect::<Vec<_>>()
        .join(" ");
    crate::fits::card_text(&camera)
}

/// `frame` as a FITS file: unsigned 16-bit samples (BITPIX 16, BZERO
/// 32768), black level included as the camera recorded it; a frame read
/// from FITS keeps its IMAGETYP.
pub fn encode_fits_frame(frame: &RawFrame) -> Result<Vec<u8>> {
    let mut cards = frame_cards(frame);
    if let Some(t) = frame.fits.as_ref().and_then(|h| h.image_type.as_deref()) {
        let text = crate::fits::card_text(t);
        cards.insert(
            0,
            FitsCard::new("IMAGETYP", FitsValue::Str(text), "frame type"),
        );
    }
    encode_fits_u16(frame.width, frame.height, &frame.mosaic, &cards)
}

/// [`encode_fits_frame`] written atomically to `path`.
pub fn write_fits_frame(frame: &RawFrame, path: &Path) -> Result<()> {
    Ok(write_atomic(path, &encode_fits_frame(frame)?)?)
}

/// A calibration master as FITS: the mean of `frames` frames, `mosaic` in
/// DN (one value per photosite of `template`'s size), written as 32-bit
/// floats normalised by 65535 (the [0, 1] convention of Siril and
/// PixInsight; pgrf reads it back at the DN scale) so the mean keeps its
/// fraction of a DN, which rounding to integers would lose (a master bias
/// of 64 frames is known to about a tenth of a DN); no SATURATE, which
/// would state an ADU level on 0-1 samples. `kind` names it in
/// IMAGETYP ("Master Bias", ...); `egain`, when given, is the measured
/// electrons per ADU (1 / K).
pub fn encode_fits_master(
    template: &RawFrame,
    mosaic: &[f32],
    kind: &str,
    frames: usize,
    egain: Option<f64>,
) -> Result<Vec<u8>> {
    check_values(template, mosaic)?;
    let mut cards = frame_cards(template);
    cards.retain(|c| c.key != "EGAIN" && c.key != SATURATE);
    cards.insert(
        0,
        FitsCard {
            key: "IMAGETYP".into(),
            value: FitsValue::Str(kind.into()),
            comment: "calibration master".into(),
        },
    );
    cards.push(float_unit_card());
    cards.push(FitsCard {
        key: "NCOMBINE".into(),
        value: FitsValue::Int(frames as i64),
        comment: "frames averaged".into(),
    });
    if let Some(g) = egain.filter(|g| g.is_finite() && *g > 0.0) {
        cards.push(FitsCard {
            key: "EGAIN".into(),
            value: FitsValue::Float(g),
            comment: "electrons per ADU (measured, 1/K)".into(),
        });
    }
    let scaled: Vec<f32> = mosaic.iter().map(|v| v / 65535.0).collect();
    encode_fits_f32(template.width, template.height, &scaled, &cards)
}

/// One value per photosite of `template`, or the refusal that says how
/// many there are and should be.
fn check_values(template: &RawFrame, mosaic: &[f32]) -> Result<()> {
    if mosaic.len() != template.width * template.height {
        return Err(RawError::MasterSize {
            values: mosaic.len(),
            width: template.width,
            height: template.height,
            needed: template.width * template.height,
        });
    }
    Ok(())
}

/// A reduced light frame as FITS: `mosaic` in DN above black (one value
/// per photosite of `template`'s size; noise takes some below 0, which is
/// kept), written as 32-bit floats normalised by 65535 as the masters are
/// ([`encode_fits_master`]), so the frames and masters pgrf writes share one
/// scale. Carries `template`'s cards (row order, Bayer pattern, EXPTIME,
/// temperature, camera, date, object, filter) but no SATURATE or EGAIN,
/// IMAGETYP 'Light Frame', BUNIT, then the caller's `cards` (the masters
/// used) and one HISTORY entry per step.
pub fn encode_fits_light(
    template: &RawFrame,
    mosaic: &[f32],
    cards: &[FitsCard],
    history: &[String],
) -> Result<Vec<u8>> {
    check_values(template, mosaic)?;
    let mut all = vec![FitsCard::new(
        "IMAGETYP",
        FitsValue::Str("Light Frame".into()),
        "calibrated light",
    )];
    // The camera's EGAIN (electrons per ADU of the raw frame) is not
    // carried: the samples are flat-divided and scaled, and a tool that
    // reads EGAIN without BUNIT would put its noise off by 65535.
    all.extend(
        frame_cards(template)
            .into_iter()
            .filter(|c| c.key != SATURATE && c.key != "EGAIN"),
    );
    all.push(float_unit_card());
    all.extend_from_slice(cards);
    let scaled: Vec<f32> = mosaic.iter().map(|v| v / 65535.0).collect();
    crate::fits::encode_fits_f32_history(template.width, template.height, &scaled, &all, history)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cfa::Cfa;
    use rand::{Rng, SeedableRng};
    use rand_xoshiro::Xoshiro256PlusPlus;

    fn frame(cfa: Option<Cfa>, seed: u64) -> RawFrame {
        let (w, h) = (10, 6);
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let data: Vec<u16> = (0..w * h).map(|_| rng.random_range(0..=60000)).collect();
        let mut f = match cfa {
            Some(c) => RawFrame::from_mosaic(w, h, data, c, [0.0; 4], 60000).unwrap(),
            None => RawFrame::from_mono(w, h, data, 0.0, 60000).unwrap(),
        };
        f.exposure_s = Some(300.0);
        f.iso = Some(800);
        f.temperature_c = Some(-10.5);
        f.model = "SBIG STL-1001".into();
        f
    }

    /// `read_temperature` takes a FITS file's and a DNG's sensor temperature
    /// from the metadata alone: a FITS file cut short of its pixels, which
    /// does not decode, still gives it; a DNG without one gives none.
    #[test]
    fn temperatures_are_read_without_the_pixels() {
        let dir = std::env::temp_dir().join(format!("pgrf-raw-temperature-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = frame(Some(Cfa::Rggb), 3);
        let bytes = encode_fits_frame(&f).unwrap();
        let cut = dir.join("cut.fits");
        std::fs::write(&cut, &bytes[..2880]).unwrap();
        assert!(crate::decode_file(&cut, &LevelOverrides::default()).is_err());
        assert_eq!(crate::read_temperature(&cut).unwrap(), Some(-10.5));
        let dng = dir.join("t.dng");
        let mut d = frame(Some(Cfa::Rggb), 4);
        d.temperature_c = Some(31.25);
        crate::write_dng(&d, &dng, &crate::DngOptions::default()).unwrap();
        assert_eq!(crate::read_temperature(&dng).unwrap(), Some(31.25));
        d.temperature_c = None;
        crate::write_dng(&d, &dng, &crate::DngOptions::default()).unwrap();
        assert_eq!(crate::read_temperature(&dng).unwrap(), None);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Written and read back: same samples, layout and metadata, for a
    /// monochrome frame and every Bayer phase.
    #[test]
    fn frames_round_trip_through_fits() {
        let mut cases: Vec<Option<Cfa>> = vec![None];
        cases.extend(Cfa::ALL.map(Some));
        for (k, cfa) in cases.into_iter().enumerate() {
            let f = frame(cfa, 7 + k as u64);
            let bytes = encode_fits_frame(&f).unwrap();
            assert_eq!(bytes.len() % 2880, 0);
            let back =
                frame_from_fits(Path::new("t.fits"), &bytes, &LevelOverrides::default()).unwrap();
            assert_eq!(back.mosaic, f.mosaic, "{cfa:?}");
            assert_eq!(back.mono, cfa.is_none());
            if let Some(c) = cfa {
                assert_eq!(back.cfa, c);
            }
            assert_eq!(
                (back.exposure_s, back.iso, back.temperature_c),
                (Some(300.0), Some(800), Some(-10.5))
            );
            assert_eq!(back.model, "SBIG STL-1001");
            assert_eq!(back.black, [0.0; 4]);
            assert_eq!(back.white, 60000, "SATURATE");
            assert_eq!(back.fits.as_ref().unwrap().bitpix, 16);
        }
    }

    /// The header cards of `bytes`, key and raw value field, up to END.
    fn cards(bytes: &[u8]) -> Vec<(String, String)> {
        bytes
            .chunks(80)
            .map(|c| String::from_utf8_lossy(c).to_string())
            .take_while(|c| !c.starts_with("END "))
            .map(|c| (c[..8].trim().to_string(), c[10..].trim().to_string()))
            .collect()
    }

    /// A FITS frame keeps its stored row order through pgrf: stated
    /// TOP-DOWN or BOTTOM-UP, or none (BOTTOM-UP by the FITS convention),
    /// it is written back as BOTTOM-UP unless it said TOP-DOWN, rows
    /// untouched, and a colour frame's BAYERPAT is restated so that the
    /// phase read back is the same (for BOTTOM-UP of even height RGGB
    /// stored is GBRG seen top-down). A frame from a camera RAW is TOP-DOWN.
    #[test]
    fn row_order_is_kept_and_stated() {
        for (stated, written) in [
            (None, "'BOTTOM-UP'"),
            (Some("BOTTOM-UP"), "'BOTTOM-UP'"),
            (Some("TOP-DOWN"), "'TOP-DOWN'"),
        ] {
            for cfa in [None, Some(Cfa::Rggb), Some(Cfa::Gbrg)] {
                let f = frame(cfa, 11);
                let mut header = vec![];
                if let Some(r) = stated {
                    header.push(FitsCard::new("ROWORDER", FitsValue::Str(r.into()), ""));
                }
                if let Some(c) = cfa {
                    header.push(FitsCard::new(
                        "BAYERPAT",
                        FitsValue::Str(c.name().into()),
                        "",
                    ));
                }
                let bytes = encode_fits_u16(f.width, f.height, &f.mosaic, &header).unwrap();
                let read =
                    frame_from_fits(Path::new("in.fits"), &bytes, &Default::default()).unwrap();
                let out = encode_fits_frame(&read).unwrap();
                let c = cards(&out);
                let value = |k: &str| c.iter().find(|(key, _)| key == k).map(|(_, v)| v.clone());
                assert!(
                    value("ROWORDER").unwrap().starts_with(written),
                    "{stated:?} {cfa:?}: {c:?}"
                );
                let back =
                    frame_from_fits(Path::new("out.fits"), &out, &Default::default()).unwrap();
                assert_eq!(back.mosaic, read.mosaic);
                assert_eq!(
                    (back.mono, back.cfa),
                    (read.mono, read.cfa),
                    "{stated:?} {cfa:?}"
                );
                assert_eq!(back.row_order(), read.row_order());
                if cfa == Some(Cfa::Rggb) && written == "'BOTTOM-UP'" {
                    // Height 6 is even: stored row 0 is top-down row 5.
                    let stored = if stated.is_some() {
                        Cfa::Gbrg
                    } else {
                        Cfa::Rggb
                    };
                    assert_eq!(read.cfa, stored, "{stated:?}");
                    let pattern = if stated.is_some() { "'RGGB" } else { "'GBRG" };
                    assert!(value("BAYERPAT").unwrap().starts_with(pattern), "{c:?}");
                }
            }
        }
        let camera = frame(Some(Cfa::Rggb), 12);
        assert_eq!(camera.row_order(), RowOrder::TopDown);
        let c = cards(&encode_fits_frame(&camera).unwrap());
        assert!(c
            .iter()
            .any(|(k, v)| k == "ROWORDER" && v.starts_with("'TOP-DOWN'")));
        assert!(c
            .iter()
            .any(|(k, v)| k == "SATURATE" && v.starts_with("60000")));
    }

    /// A reduced light reads back unrounded (`read_fits_samples`), with
    /// its cards, its HISTORY (a long entry over two cards) before END,
    /// and no SATURATE.
    #[test]
    fn lights_keep_fractions_and_history() {
        let f = frame(Some(Cfa::Rggb), 5);
        let mosaic: Vec<f32> = (0..f.width * f.height)
            .map(|i| 500.25 + i as f32 * 1.5)
            .collect();
        let named = [FitsCard::new(
            "MBIAS",
            FitsValue::Str("master_bias.fits".into()),
            "",
        )];
        let history = ["first step".to_string(), "x".repeat(100)];
        let bytes = encode_fits_light(&f, &mosaic, &named, &history).unwrap();
        let (img, samples) = crate::fits::read_fits_samples(Path::new("l.fits"), &bytes).unwrap();
        assert_eq!(img.exposure_s, Some(300.0));
        for (a, b) in samples.iter().zip(&mosaic) {
            assert!((a - b).abs() <= 1e-3, "{a} vs {b}");
        }
        let c = cards(&bytes);
        let history_cards: Vec<_> = c.iter().filter(|(k, _)| k == "HISTORY").collect();
        assert_eq!(history_cards.len(), 3, "{c:?}");
        assert!(c
            .iter()
            .any(|(k, v)| k == "MBIAS" && v.starts_with("'master_bias.fits'")));
        assert!(c
            .iter()
            .any(|(k, v)| k == "IMAGETYP" && v.starts_with("'Light Frame'")));
        assert!(!c.iter().any(|(k, _)| k == "SATURATE"));
        assert!(encode_fits_light(&f, &mosaic[1..], &named, &history).is_err());
    }

    /// A master keeps its fractional DN to float precision (relative
    /// 2^-24 of 65535: well under 0.01 DN).
    #[test]
    fn masters_keep_fractions_of_a_dn() {
        let f = frame(None, 3);
        let mosaic: Vec<f32> = (0..f.width * f.height)
            .map(|i| 1000.0 + i as f32 * 0.37)
            .collect();
        let bytes = encode_fits_master(&f, &mosaic, "Master Bias", 64, Some(2.06)).unwrap();
        let img = read_fits(Path::new("m.fits"), &bytes).unwrap();
        assert_eq!(img.bitpix, -32);
        // Samples in 0-1 carry no ADU saturation level.
        assert!(!cards(&bytes).iter().any(|(k, _)| k == "SATURATE"));
        assert_eq!(img.egain_e_per_adu, Some(2.06));
        // Read as DN, rounded.
        for (a, b) in img.data.iter().zip(&mosaic) {
            assert!((*a as f32 - b).abs() <= 0.5, "{a} vs {b}");
        }
        // The stored floats themselves: big-endian after the header's
        // 2880-byte blocks (the header ends with the END card).
        let end = (0..bytes.len() / 80)
            .find(|i| bytes[i * 80..i * 80 + 8] == *b"END     ")
            .unwrap();
        let start = ((end + 1) * 80).div_ceil(2880) * 2880;
        for (i, b) in mosaic.iter().enumerate() {
            let o = start + 4 * i;
            let v = f32::from_be_bytes(bytes[o..o + 4].try_into().unwrap()) * 65535.0;
            assert!((v - b).abs() < 0.01, "{v} vs {b}");
        }
        assert!(encode_fits_master(&f, &mosaic[1..], "Master Bias", 64, None).is_err());
    }
}
