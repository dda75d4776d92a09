//! What pgrf reads from a RAW file, as one record: `pgrf info` prints it as
//! text or serialises it (`--json`). Here, beside [`crate::lookup`],
//! because the record includes what a noise-aware model would be told of
//! the frame's noise, found once for both forms.

use crate::error::{NoiseError, Result};
use crate::lookup::{find_noise, FrameNoise, KnownNoise};
use pgrf_raw::stats::{plane_stats, PlaneStats};
use pgrf_raw::{ColorMatrix, FitsHeader, RawFrame};
use serde::{Serialize, Serializer};
use std::path::Path;

/// A frame's record (the keys of `pgrf info --json`).
#[derive(Serialize)]
pub struct FrameInfo<'a> {
    /// The file as named.
    pub file: String,
    /// Camera maker.
    pub make: &'a str,
    /// Camera model.
    pub model: &'a str,
    /// Visible width, pixels.
    pub width: usize,
    /// Visible height, pixels.
    pub height: usize,
    /// "mono" or the CFA's name.
    pub cfa: String,
    /// One black level for a monochrome frame whose planes share it, else
    /// the four of R, G1, B, G2 (or the sub-lattices').
    pub black: Vec<f32>,
    /// Saturation level, DN.
    pub white: u32,
    /// Bits per sample.
    pub bits: u32,
    /// As-shot white balance R, G, B.
    pub wb: Option<[f32; 3]>,
    /// Every XYZ->camera matrix of the file.
    pub color_matrices: &'a [ColorMatrix],
    /// ISO, when recorded.
    pub iso: Option<u32>,
    /// Exposure time, seconds.
    pub exposure_s: Option<f64>,
    /// Temperature at capture, °C.
    pub temperature_c: Option<f32>,
    /// The DNG NoiseProfile's (S, O) pairs, when the file has one.
    pub noise_profile: Option<&'a [[f64; 2]]>,
    /// What a noise-aware model would be told of the frame's noise
    /// ([`find_noise`]): K, read and row noise in DN and the source, or why
    /// none was found (serialised as `noise_parameters`).
    #[serde(rename = "noise_parameters", serialize_with = "noise_json")]
    pub noise: std::result::Result<FrameNoise, NoiseError>,
    /// FITS header fields beyond the common ones (FITS input only).
    pub fits: Option<&'a FitsHeader>,
    /// EXIF orientation.
    pub orientation: u16,
    /// Where the visible area starts on the readout (row, col).
    pub visible_origin: [usize; 2],
    /// The readout's size (height, width).
    pub sensor_size: [usize; 2],
    /// Each plane's samples (one plane for a monochrome frame).
    pub planes: Vec<PlaneStats>,
}

impl<'a> FrameInfo<'a> {
    /// The record of frame `f`, read from `file`; `darktable` names
    /// darktable's noiseprofiles.json for the noise lookup (else its
    /// install is searched).
    pub fn of(file: &Path, f: &'a RawFrame, darktable: Option<&Path>) -> Result<FrameInfo<'a>> {
        Ok(FrameInfo {
            file: file.display().to_string(),
            make: &f.make,
            model: &f.model,
            width: f.width,
            height: f.height,
            cfa: f.layout().to_string(),
            black: black_levels(f),
            white: f.white,
            bits: f.bits,
            wb: f.wb,
            color_matrices: &f.color_matrices,
            iso: f.iso,
            exposure_s: f.exposure_s,
            temperature_c: f.temperature_c,
            noise_profile: f.noise_profile.as_deref(),
            noise: match not_a_photo(f) {
                Some(why) => Err(NoiseError::NotAPhoto { why }),
                None => find_noise(
                    f,
                    &KnownNoise {
                        darktable: darktable.map(Path::to_path_buf),
                        ..KnownNoise::default()
                    },
                ),
            },
            fits: f.fits.as_ref(),
            orientation: f.orientation,
            visible_origin: [f.sensor_origin.0, f.sensor_origin.1],
            sensor_size: [f.sensor_size.0, f.sensor_size.1],
            planes: plane_stats(f).map_err(|error| NoiseError::Frame { error })?,
        })
    }
}

/// Why the noise a model would be told means nothing for `f`, if it does
/// not: a FITS calibration frame (its noise is the sensor's, which `pgrf
/// calibrate` measures from a stack; a flat's is mostly shot noise at one
/// level, a bias's has no signal) or a FITS frame stored as the camera read
/// it with no black level (an estimate would count the bias pedestal as
/// signal). A bias-subtracted frame (pgrf's reduced lights, 32-bit floats)
/// has its black at 0 and is estimated.
fn not_a_photo(f: &RawFrame) -> Option<String> {
    let h = f.fits.as_ref()?;
    if let Some(t) = h.calibration_type() {
        return Some(format!(
            "IMAGETYP '{t}': a calibration frame, not a light; its noise is the sensor's, which `pgrf calibrate` measures from a stack of them"
        ));
    }
    if h.conversion.is_none() && f.black.iter().all(|&b| b == 0.0) {
        return Some(
            "the FITS file records no black level, so an estimate from its pixels would count the bias pedestal as signal; give --black, or calibrate with bias frames"
                .into(),
        );
    }
    None
}

/// The black levels to show: one for a monochrome frame (one signal, one
/// level) unless overrides gave its sub-lattices different ones.
fn black_levels(f: &RawFrame) -> Vec<f32> {
    if f.mono && f.black.iter().all(|&b| b == f.black[0]) {
        vec![f.black[0]]
    } else {
        f.black.to_vec()
    }
}

fn noise_json<S: Serializer>(
    noise: &std::result::Result<FrameNoise, NoiseError>,
    s: S,
) -> std::result::Result<S::Ok, S::Error> {
    match noise {
        Ok(n) => serde_json::json!({
            "K": n.k, "read": n.read, "row": n.row, "source": n.source.to_string()
        }),
        Err(e) => serde_json::json!({ "error": e.to_string() }),
    }
    .serialize(s)
}
