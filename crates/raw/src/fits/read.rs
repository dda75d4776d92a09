//! Reading a FITS frame: the primary HDU through fitsrs, BZERO/BSCALE applied,
//! brought to u16 ADU or refused with the reason; the Bayer phase and the
//! header values pgrf keeps.

use super::keyword::{binning, integer, number, row_order, show, string, text, KeywordError};
use super::*;

use crate::cfa::Cfa;
use crate::error::{RawError, Result};
use crate::panic_guard;
use fitsrs::card::Value;
use fitsrs::hdu::header::ValueMap;
use fitsrs::{Fits, Pixels, HDU};
use std::io::Cursor;
use std::path::Path;

/// Whether `bytes` start like a FITS file: the first card is `SIMPLE = T`.
///
/// Used to route a file to [`read_fits`] before any camera-RAW decoder sees
/// it.
pub fn is_fits(bytes: &[u8]) -> bool {
    if bytes.len() < CARD || &bytes[..9] != b"SIMPLE  =" {
        return false;
    }
    let value = value_field(&bytes[..CARD]);
    value == Some("T")
}

/// Read the primary image of a FITS file held in memory.
///
/// `name` is only used in error messages. The header is checked before any
/// buffer is sized from it; every refusal is one line naming the keyword or
/// value at fault. See the module documentation for the Bayer convention.
pub fn read_fits(name: &Path, bytes: &[u8]) -> Result<FitsImage> {
    with_primary(name, bytes, |fits, hdu| {
        read_primary(name, bytes, fits, hdu)
    })
}

/// A reader of a FITS file held in memory, and its primary HDU.
type Reader<'b> = Fits<Cursor<&'b [u8]>>;
type Primary = fitsrs::fits::HDU<fitsrs::hdu::header::extension::image::Image>;

/// `f` of the primary HDU of a FITS file held in memory (and its reader,
/// for the data), after the checks every reader of it makes: not empty,
/// `SIMPLE = T`, no axis pgrf cannot use (fitsrs multiplies the axis
/// lengths while it parses, and would overflow on hostile ones). fitsrs
/// asserts on some malformed input; a panic there becomes an error.
fn with_primary<T>(
    name: &Path,
    bytes: &[u8],
    f: impl FnOnce(&mut Reader<'_>, Primary) -> Result<T>,
) -> Result<T> {
    if bytes.is_empty() {
        return Err(RawError::decode(name, "file is empty"));
    }
    if !is_fits(bytes) {
        return Err(RawError::decode(
            name,
            "not a FITS file: the first card is not SIMPLE = T",
        ));
    }
    if let Some(why) = oversized_axis(bytes) {
        return Err(RawError::decode(name, why));
    }
    panic_guard::quietly(|| {
        let mut fits = Fits::from_reader(Cursor::new(bytes));
        match fits.next() {
            Some(Ok(HDU::Primary(hdu))) => f(&mut fits, hdu),
            Some(Ok(_)) | None => Err(RawError::decode(name, "no primary HDU")),
            Some(Err(e)) => Err(RawError::decode(name, header_error(bytes, &e))),
        }
    })
    .map_err(|panic| RawError::decode(name, panic.to_string()))?
}

/// The samples of a FITS file in DN as floats, unrounded, beside what
/// [`read_fits`] reads of it (the file is checked and refused as there): a
/// master written as 32-bit floats (`encode_fits_master`) knows its mean to
/// a fraction of a DN, which [`FitsImage::data`]'s integers round away, and
/// light-frame reduction subtracts it unrounded as every stacking program
/// does. Normalised 0..1 floats are scaled by 65535 as [`read_fits`] scales
/// them; integer samples are the same values as [`FitsImage::data`].
pub fn read_fits_samples(name: &Path, bytes: &[u8]) -> Result<(FitsImage, Vec<f32>)> {
    let image = read_fits(name, bytes)?;
    if image.bitpix > 0 {
        let samples = image.data.iter().map(|&v| f32::from(v)).collect();
        return Ok((image, samples));
    }
    let scale = if (image.conversion.as_deref()).is_some_and(|c| c.ends_with("scaled by 65535")) {
        65535.0
    } else {
        1.0
    };
    let n = image.width * image.height;
    let decode = |m: String| RawError::decode(name, m);
    let keyword = |e| RawError::fits_keyword(name, e);
    let samples = panic_guard::quietly(|| -> Result<Vec<f32>> {
        let mut fits = Fits::from_reader(Cursor::new(bytes));
        let Some(Ok(HDU::Primary(hdu))) = fits.next() else {
            return Err(decode("no primary HDU".into()));
        };
        let header = hdu.get_header();
        let bzero = number(header, "BZERO").map_err(keyword)?.unwrap_or(0.0);
        let bscale = number(header, "BSCALE").map_err(keyword)?.unwrap_or(1.0);
        let physical = |v: f64| ((bzero + bscale * v) * scale) as f32;
        let samples: Vec<f32> = match fits.get_data(&hdu).pixels() {
            Pixels::F32(it) => it.take(n).map(|v| physical(f64::from(v))).collect(),
            Pixels::F64(it) => it.take(n).map(physical).collect(),
            _ => return Err(decode("BITPIX changed between two reads".into())),
        };
        Ok(samples)
    })
    .map_err(|panic| decode(panic.to_string()))??;
    Ok((image, samples))
}

fn read_primary(
    name: &Path,
    bytes: &[u8],
    fits: &mut Reader<'_>,
    hdu: Primary,
) -> Result<FitsImage> {
    let decode = |m: String| RawError::decode(name, m);
    let unsupported = |m: String| RawError::unsupported(name, m);
    let header = hdu.get_header();
    let image = header.get_xtension();
    let naxis: Vec<u64> = image.get_naxis().to_vec();
    let bitpix = image.get_bitpix() as i8 as i32;
    let data_start = usize::try_from(hdu.get_data_unit_byte_offset())
        .map_err(|_| decode("data offset does not fit in memory".into()))?;
    let (width, height) = geometry(name, bytes, &naxis, bitpix, data_start)?;
    let n = width * height;
    let keyword = |e| RawError::fits_keyword(name, e);
    let scaling = Scaling::of(header, bitpix).map_err(keyword)?;
    let meta = Metadata::of(name, header, height)?;

    // Pixels.
    let Scaling {
        bzero,
        bscale,
        blank,
    } = scaling;
    let (data, conversion) = match fits.get_data(&hdu).pixels() {
        Pixels::U8(it) => integers(it.map(i64::from), n, 8, bzero, bscale, blank),
        Pixels::I16(it) => integers(it.map(i64::from), n, 16, bzero, bscale, blank),
        Pixels::I32(it) => integers(it.map(i64::from), n, 32, bzero, bscale, blank),
        Pixels::I64(it) => integers(it, n, 64, bzero, bscale, blank),
        Pixels::F32(it) => floats(it.map(f64::from), n, -32, bzero, bscale),
        Pixels::F64(it) => floats(it, n, -64, bzero, bscale),
    }
    .map_err(|m| match m {
        Refusal::Decode(m) => decode(m),
        Refusal::Unsupported(m) => unsupported(m),
    })?;
    let (white, white_conflict) =
        white_level(header, &data, bitpix, &scaling, conversion.as_deref()).map_err(keyword)?;

    Ok(FitsImage {
        width,
        height,
        data,
        bayer: meta.bayer,
        row_order: meta.row_order,
        bitpix,
        white,
        exposure_s: meta.exposure.map(|(_, t)| t),
        egain_e_per_adu: meta.egain_e_per_adu,
        gain_setting: meta.gain_setting,
        temperature_c: meta.temperature.map(|(_, t)| t as f32),
        iso: meta.iso,
        instrument: meta.instrument,
        date_obs: meta.date_obs,
        image_type: meta.image_type,
        filter: meta.filter,
        object: meta.object,
        binning: meta.binning,
        conversion,
        white_conflict,
    })
}

/// The image's width and height from NAXIS, checked before anything is
/// sized from the header: a 2-D frame (or a cube of one plane) of sides
/// 2..=MAX_SIDE whose samples the file holds and memory can take.
fn geometry(
    name: &Path,
    bytes: &[u8],
    naxis: &[u64],
    bitpix: i32,
    data_start: usize,
) -> Result<(usize, usize)> {
    let decode = |m: String| RawError::decode(name, m);
    let unsupported = |m: String| RawError::unsupported(name, m);
    let (width, height) = match naxis {
        [] => return Err(empty_primary(name, bytes, data_start)),
        [w, h] | [w, h, 1] => (*w, *h),
        [_, _, 3] => {
            return Err(unsupported(
                "already demosaiced colour (3 planes); pgrf needs the sensor's raw frame".into(),
            ))
        }
        [_, _, n] => {
            return Err(unsupported(format!(
                "NAXIS3 = {n}: a cube of {n} planes; pgrf reads one 2-D frame"
            )))
        }
        other => {
            return Err(unsupported(format!(
                "NAXIS = {}: pgrf reads 2-D images (NAXIS 2, or 3 with NAXIS3 = 1)",
                other.len()
            )))
        }
    };
    for (key, v) in [("NAXIS1", width), ("NAXIS2", height)] {
        if !(2..=MAX_SIDE).contains(&v) {
            return Err(decode(format!(
                "{key} = {v} is outside 2..={MAX_SIDE} pixels"
            )));
        }
    }
    if let Some(why) = crate::container::limits::too_many_pixels(width, height) {
        return Err(decode(why));
    }
    let sample_bytes = u64::from(bitpix.unsigned_abs() / 8);
    let need = width * height * sample_bytes; // <= 65536^2 * 8: no overflow
    let have = (bytes.len() - data_start.min(bytes.len())) as u64;
    if need > have {
        return Err(decode(format!(
            "truncated: the image needs {need} bytes after the header, the file has {have}"
        )));
    }
    let (width, height) = (width as usize, height as usize);
    crate::memory::check_frame(name, "decoding", width, height, crate::memory::DECODE)?;
    Ok((width, height))
}

/// BZERO, BSCALE and (for integer images) BLANK.
struct Scaling {
    bzero: f64,
    bscale: f64,
    blank: Option<i64>,
}

impl Scaling {
    fn of(header: &ValueMap, bitpix: i32) -> std::result::Result<Scaling, KeywordError> {
        let bzero = number(header, "BZERO")?.unwrap_or(0.0);
        let bscale = number(header, "BSCALE")?.unwrap_or(1.0);
        if bscale == 0.0 {
            return Err(KeywordError::ZeroScale);
        }
        let blank = if bitpix > 0 {
            integer(header, "BLANK")?
        } else {
            None
        };
        Ok(Scaling {
            bzero,
            bscale,
            blank,
        })
    }
}

/// The sensor temperature a header records (CCD-TEMP, else CCD_TEMP), with
/// its keyword; refused outside -273.15..200 degrees C.
fn temperature(name: &Path, header: &ValueMap) -> Result<Option<(&'static str, f64)>> {
    for key in ["CCD-TEMP", "CCD_TEMP"] {
        let Some(t) = number(header, key).map_err(|e| RawError::fits_keyword(name, e))? else {
            continue;
        };
        if !(-273.15..=200.0).contains(&t) {
            return Err(RawError::decode(
                name,
                format!("{key} = {t} is not a sensor temperature in degrees Celsius"),
            ));
        }
        return Ok(Some((key, t)));
    }
    Ok(None)
}

/// The sensor temperature of a FITS file held in memory, from its primary
/// header alone (no pixel is converted): what calibration groups
/// temperature darks by before reading each group once.
pub fn fits_temperature(name: &Path, bytes: &[u8]) -> Result<Option<f32>> {
    with_primary(name, bytes, |_, hdu| temperature(name, hdu.get_header()))
        .map(|t| t.map(|(_, t)| t as f32))
}

/// The header values pgrf keeps, checked before the pixels are converted;
/// exposure and temperature with the keyword they came from.
struct Metadata {
    exposure: Option<(&'static str, f64)>,
    egain_e_per_adu: Option<f64>,
    gain_setting: Option<f64>,
    temperature: Option<(&'static str, f64)>,
    iso: Option<u32>,
    instrument: Option<String>,
    date_obs: Option<String>,
    image_type: Option<String>,
    filter: Option<String>,
    object: Option<String>,
    binning: Option<(u32, u32)>,
    row_order: Option<RowOrder>,
    bayer: Option<Cfa>,
}

impl Metadata {
    fn of(name: &Path, header: &ValueMap, height: usize) -> Result<Metadata> {
        let decode = |m: String| RawError::decode(name, m);
        let keyword = |e| RawError::fits_keyword(name, e);
        let first = |keys: [&'static str; 2]| -> Result<Option<(&'static str, f64)>> {
            for key in keys {
                if let Some(v) = number(header, key).map_err(keyword)? {
                    return Ok(Some((key, v)));
                }
            }
            Ok(None)
        };
        let exposure = first(["EXPTIME", "EXPOSURE"])?;
        if let Some((key, t)) = exposure {
            if t < 0.0 {
                return Err(decode(format!("{key} = {t} s is negative")));
            }
        }
        let egain_e_per_adu = number(header, "EGAIN").map_err(keyword)?;
        if let Some(g) = egain_e_per_adu {
            if g <= 0.0 {
                return Err(decode(format!("EGAIN = {g} e-/ADU is not positive")));
            }
        }
        let gain_setting = number(header, "GAIN").map_err(keyword)?;
        let temperature = temperature(name, header)?;
        let iso = match integer(header, "ISOSPEED").map_err(keyword)? {
            None => None,
            Some(v) if (1..=i64::from(u32::MAX)).contains(&v) => Some(v as u32),
            Some(v) => return Err(decode(format!("ISOSPEED = {v} is not a positive ISO"))),
        };
        let instrument = string(header, "INSTRUME").map_err(keyword)?;
        let date_obs = string(header, "DATE-OBS").map_err(keyword)?;
        let image_type = text(header, "IMAGETYP");
        let filter = text(header, "FILTER");
        let object = text(header, "OBJECT");
        let binning = binning(header).map_err(keyword)?;
        let row_order = row_order(header).map_err(keyword)?;
        Ok(Metadata {
            exposure,
            egain_e_per_adu,
            gain_setting,
            temperature,
            iso,
            instrument,
            date_obs,
            image_type,
            filter,
            object,
            binning,
            row_order,
            bayer: bayer_phase(name, header, height, row_order)?,
        })
    }
}

/// The frame's white level: full scale (255 for plain 8-bit data), or the
/// header's SATURATE / DATAMAX where no sample exceeds it; a level that
/// samples exceed leaves full scale and is reported as a conflict (the
/// frame is then refused unless --white settles it). Normalised float
/// frames are full scale.
fn white_level(
    header: &ValueMap,
    data: &[u16],
    bitpix: i32,
    s: &Scaling,
    conversion: Option<&str>,
) -> std::result::Result<(u32, Option<String>), KeywordError> {
    let normalised = bitpix < 0 && conversion.is_some_and(|c| c.ends_with("scaled by 65535"));
    let max_sample = u32::from(data.iter().copied().max().unwrap_or(0));
    let white = if bitpix == 8 && s.bzero == 0.0 && s.bscale == 1.0 {
        255
    } else {
        65535
    };
    if normalised {
        return Ok((white, None));
    }
    for key in ["SATURATE", "DATAMAX"] {
        if let Some(v) = number(header, key)? {
            if v.fract() == 0.0 && v >= 1.0 && v < f64::from(white) {
                if v < f64::from(max_sample) {
                    let above = data.iter().filter(|&&x| f64::from(x) > v).count();
                    let n = data.len();
                    return Ok((white, Some(format!(
                        "{key} = {v} lies below {above} of the {n} samples (the largest is {max_sample}): the header's saturation level contradicts the data; --white sets the level to use ({v} clips the samples above it, {white} is full scale)"
                    ))));
                }
                return Ok((v as u32, None));
            }
        }
    }
    Ok((white, None))
}

/// Why the pixels cannot be used: damaged (NaN, BLANK) or of a kind pgrf
/// does not handle (calibrated, out of range).
enum Refusal {
    Decode(String),
    Unsupported(String),
}

/// Integer samples: physical = BZERO + BSCALE * stored must be an integer
/// in 0..=65535.
fn integers(
    stored: impl Iterator<Item = i64>,
    n: usize,
    bitpix: i32,
    bzero: f64,
    bscale: f64,
    blank: Option<i64>,
) -> std::result::Result<(Vec<u16>, Option<String>), Refusal> {
    // The common case (BZERO an integer, BSCALE 1) in exact integer arithmetic.
    let exact_offset =
        (bscale == 1.0 && bzero.fract() == 0.0 && bzero.abs() < 1e18).then_some(bzero as i128);
    let mut out = Vec::with_capacity(n);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut blanks, mut fractional) = (0usize, 0usize);
    for s in stored.take(n) {
        if Some(s) == blank {
            blanks += 1;
            out.push(0);
            continue;
        }
        let v = match exact_offset {
            Some(z) => {
                let p = i128::from(s) + z;
                lo = lo.min(p as f64);
                hi = hi.max(p as f64);
                p
            }
            None => {
                let p = bzero + bscale * s as f64;
                lo = lo.min(p);
                hi = hi.max(p);
                let r = p.round();
                if (p - r).abs() > 1e-6 {
                    fractional += 1;
                }
                r as i128
            }
        };
        out.push(u16::try_from(v).unwrap_or(0));
    }
    if out.len() != n {
        return Err(Refusal::Decode(format!(
            "truncated: the image has {} of its {n} samples",
            out.len()
        )));
    }
    if blanks > 0 {
        return Err(Refusal::Decode(format!(
            "{blanks} samples equal BLANK = {} (undefined pixels); pgrf needs every pixel",
            blank.unwrap_or(0)
        )));
    }
    let scaled = if bzero != 0.0 || bscale != 1.0 {
        " after BZERO/BSCALE"
    } else {
        ""
    };
    if fractional > 0 {
        return Err(Refusal::Unsupported(format!(
            "{fractional} BITPIX {bitpix} samples are not integers{scaled} \
             (BZERO = {bzero}, BSCALE = {bscale}); pgrf needs integer ADU"
        )));
    }
    if lo < 0.0 || hi > 65535.0 {
        return Err(Refusal::Unsupported(format!(
            "BITPIX {bitpix} values span {lo}..{hi}{scaled}; pgrf needs ADU in 0..65535{}",
            if lo < 0.0 {
                " (negative values: a calibrated frame, or signed data without BZERO = 32768?)"
            } else {
                ""
            }
        )));
    }
    Ok((out, integer_conversion(bitpix, bzero, bscale, scaled)))
}

/// What was done to integer samples to make them u16 ADU, None for plain
/// (or BZERO-offset) BITPIX 16.
fn integer_conversion(bitpix: i32, bzero: f64, bscale: f64, scaled: &str) -> Option<String> {
    match bitpix {
        16 if bscale == 1.0 => None,
        16 => Some(format!(
            "BITPIX 16 scaled by BZERO = {bzero}, BSCALE = {bscale}"
        )),
        8 => Some(format!("BITPIX 8 widened to 16 bits{scaled}")),
        _ => Some(format!(
            "BITPIX {bitpix} integers{scaled}, all within 0..65535"
        )),
    }
}

/// Floating-point samples: no NaN or infinity; normalised 0..1 data (Siril,
/// PixInsight) are scaled by 65535, 0..65535 data rounded, anything else
/// (negative: a calibrated frame) refused.
fn floats<T: Copy + Into<f64>>(
    stored: impl Iterator<Item = T>,
    n: usize,
    bitpix: i32,
    bzero: f64,
    bscale: f64,
) -> std::result::Result<(Vec<u16>, Option<String>), Refusal> {
    // Kept in the stored type (at most the file's own size) for the second
    // pass once the range is known.
    let values: Vec<T> = stored.take(n).collect();
    if values.len() != n {
        return Err(Refusal::Decode(format!(
            "truncated: the image has {} of its {n} samples",
            values.len()
        )));
    }
    let physical = |v: T| bzero + bscale * v.into();
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut nan, mut inf) = (0usize, 0usize);
    for &v in &values {
        let p = physical(v);
        if p.is_nan() {
            nan += 1;
        } else if p.is_infinite() {
            inf += 1;
        } else {
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    if nan + inf > 0 {
        return Err(Refusal::Decode(format!(
            "{nan} NaN and {inf} infinite samples of {n} (BITPIX {bitpix}); \
             pgrf needs a value for every pixel"
        )));
    }
    let (scale, conversion) = if lo >= 0.0 && hi <= 1.0 {
        (65535.0, format!("BITPIX {bitpix} in 0..1 scaled by 65535"))
    } else if lo >= 0.0 && hi <= 65535.0 {
        (
            1.0,
            format!("BITPIX {bitpix} in 0..65535 rounded to integers"),
        )
    } else {
        return Err(Refusal::Unsupported(format!(
            "BITPIX {bitpix} values span {lo}..{hi}: neither normalised 0..1 nor ADU 0..65535{}; \
             pgrf needs the camera's raw frame",
            if lo < 0.0 {
                " (negative values: probably a calibrated frame)"
            } else {
                ""
            }
        )));
    };
    let data = values
        .into_iter()
        .map(|v| (physical(v) * scale).round().clamp(0.0, 65535.0) as u16)
        .collect();
    Ok((data, Some(conversion)))
}

/// The phase of `data[0]` from BAYERPAT, XBAYROFF, YBAYROFF and ROWORDER
/// (`rows`, module documentation).
fn bayer_phase(
    name: &Path,
    header: &ValueMap,
    height: usize,
    rows: Option<RowOrder>,
) -> Result<Option<Cfa>> {
    let no_phase = || {
        RawError::unsupported(
            name,
            "BAYERPAT = T says the sensor has a colour filter but not its phase; \
             pgrf needs RGGB, BGGR, GRBG or GBRG",
        )
    };
    let pattern = match header.get("BAYERPAT") {
        None | Some(Value::Undefined) | Some(Value::Logical { value: false, .. }) => {
            return Ok(None)
        }
        Some(Value::Logical { value: true, .. }) => return Err(no_phase()),
        Some(Value::String { value, .. }) => {
            let v = value.trim().to_ascii_uppercase();
            if v.is_empty() {
                return Ok(None);
            }
            if v == "TRUE" || v == "T" {
                return Err(no_phase());
            }
            v.parse::<Cfa>().map_err(|_| {
                RawError::unsupported(
                    name,
                    format!("BAYERPAT = '{v}' is not a 2x2 Bayer phase (RGGB, BGGR, GRBG or GBRG)"),
                )
            })?
        }
        Some(other) => {
            return Err(RawError::decode(
                name,
                format!("BAYERPAT = {} is not a Bayer pattern name", show(other)),
            ))
        }
    };
    let keyword = |e| RawError::fits_keyword(name, e);
    let xoff = integer(header, "XBAYROFF").map_err(keyword)?.unwrap_or(0);
    let yoff = integer(header, "YBAYROFF").map_err(keyword)?.unwrap_or(0);
    let bottom_up = rows == Some(RowOrder::BottomUp);
    Ok(Some(stored_phase(pattern, xoff, yoff, bottom_up, height)))
}

/// BAYERPAT (top-down convention) to the phase of stored row 0, column 0.
pub(crate) fn stored_phase(
    pattern: Cfa,
    xoff: i64,
    yoff: i64,
    bottom_up: bool,
    height: usize,
) -> Cfa {
    let flip = if bottom_up { (height + 1) % 2 } else { 0 }; // (H - 1) mod 2
    let dy = (yoff.rem_euclid(2) as usize + flip) % 2;
    let dx = xoff.rem_euclid(2) as usize;
    pattern.shifted(dy, dx)
}

/// Turn a fitsrs header error into a message naming what is wrong, looking
/// at the mandatory cards ourselves where fitsrs's words do not.
fn header_error(bytes: &[u8], e: &fitsrs::error::Error) -> String {
    use fitsrs::error::Error;
    match e {
        Error::Io(std::io::ErrorKind::UnexpectedEof) => {
            return "the header has no END card before the end of the file (truncated?)".into()
        }
        Error::StaticError("EOF reached") => {
            return "truncated: the file ends inside the header's 2880-byte block".into()
        }
        _ => {}
    }
    let cards = raw_cards(bytes, 0);
    let get = |key: &str| cards.iter().find(|(k, _)| *k == key).map(|(_, v)| *v);
    match get("BITPIX") {
        None => return "the mandatory BITPIX card is missing".into(),
        Some(Some(b)) if ["8", "16", "32", "64", "-32", "-64"].contains(&b) => {}
        Some(b) => {
            return format!(
                "BITPIX = {} is not a FITS sample type (8, 16, 32, 64, -32 or -64)",
                b.unwrap_or("(blank)")
            )
        }
    }
    let naxis = match get("NAXIS") {
        Some(Some(v)) => match v.parse::<u64>() {
            Ok(n) if n <= 999 => n,
            _ => return format!("NAXIS = {v} is not an axis count (0..=999)"),
        },
        _ => return "the mandatory NAXIS card is missing or blank".into(),
    };
    for i in 1..=naxis {
        let key = format!("NAXIS{i}");
        match get(&key) {
            Some(Some(v)) if v.parse::<u64>().is_ok() => {}
            Some(Some(v)) => return format!("{key} = {v} is not an axis length"),
            _ => return format!("{key} is missing (NAXIS = {naxis})"),
        }
    }
    format!("cannot parse the primary header: {e}")
}

/// An axis length that pgrf refuses whatever the rest of the header says:
/// NAXIS1 or NAXIS2 outside 2..=65536, or a further axis above 65536.
fn oversized_axis(bytes: &[u8]) -> Option<String> {
    raw_cards(bytes, 0).into_iter().find_map(|(key, value)| {
        let axis: u32 = key.strip_prefix("NAXIS")?.parse().ok()?;
        let v: i128 = value?.parse().ok()?;
        match axis {
            1 | 2 if !(2..=i128::from(MAX_SIDE)).contains(&v) => {
                Some(format!("{key} = {v} is outside 2..={MAX_SIDE} pixels"))
            }
            3.. if v > i128::from(MAX_SIDE) => Some(format!(
                "{key} = {v}: a cube of that many planes; pgrf reads one 2-D frame"
            )),
            _ => None,
        }
    })
}

/// Why a primary HDU without an image cannot be read; a tile-compressed
/// (fpack) file is recognised from its first extension's header, scanned
/// here without fitsrs so that none of its values sizes a buffer.
fn empty_primary(name: &Path, bytes: &[u8], next_header: usize) -> RawError {
    let cards = raw_cards(bytes, next_header);
    let get = |key: &str| cards.iter().find(|(k, _)| *k == key).and_then(|(_, v)| *v);
    match get("XTENSION") {
        None => RawError::decode(
            name,
            "the primary HDU holds no image (NAXIS = 0) and no extension follows",
        ),
        Some(x) if x.trim_matches('\'').trim() == "BINTABLE" && get("ZIMAGE") == Some("T") => {
            RawError::unsupported(
                name,
                "tile-compressed (fpack) image: the primary HDU is empty and the image is in a \
                 compressed binary-table extension; decompress it first with funpack",
            )
        }
        Some(x) => RawError::unsupported(
            name,
            format!(
                "the primary HDU holds no image (NAXIS = 0); pgrf reads only the primary image, \
                 and the first extension is XTENSION = {x}"
            ),
        ),
    }
}

/// The (keyword, value field) of the cards from `start` up to END or the end
/// of the file, at most 100 blocks: a bounded look at a header for messages.
fn raw_cards(bytes: &[u8], start: usize) -> Vec<(&str, Option<&str>)> {
    let Some(rest) = bytes.get(start..) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for card in rest.chunks_exact(CARD).take(100 * BLOCK / CARD) {
        let key = std::str::from_utf8(&card[..8]).unwrap_or("").trim_end();
        if key == "END" {
            break;
        }
        out.push((key, value_field(card)));
    }
    out
}

/// The value of a `KEY     = value / comment` card, trimmed; `None` when the
/// card has no value indicator or a blank value.
pub(super) fn value_field(card: &[u8]) -> Option<&str> {
    if card.len() < 10 || &card[8..10] != b"= " {
        return None;
    }
    let text = std::str::from_utf8(&card[10..]).ok()?;
    let value = if text.trim_start().starts_with('\'') {
        // A string: up to its closing quote ('' is an escaped quote).
        let t = text.trim_start();
        let mut end = None;
        let b = t.as_bytes();
        let mut i = 1;
        while i < b.len() {
            if b[i] == b'\'' {
                if b.get(i + 1) == Some(&b'\'') {
                    i += 2;
                    continue;
                }
                end = Some(i + 1);
                break;
            }
            i += 1;
        }
        &t[..end.unwrap_or(t.len())]
    } else {
        text.split('/').next().unwrap_or("")
    };
    let value = value.trim();
    (!value.is_empty()).then_some(value)
}

// ---------------------------------------------------------------- writing
