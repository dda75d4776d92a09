//! The calibration file: per-pixel maps in safetensors plus one JSON record of
//! how they were measured, and its conversion into the noise model's maps.

use crate::error::{CalibError, RecordFault, Result};
use crate::estimate::{defect, GainMethod};
use ndarray::Array3;
use pgrf_noise::mapfile::write_maps;
use pgrf_noise::{DarkLaw, Map, PixelMaps};
use pgrf_raw::Cfa;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

/// Everything about how a calibration was made; units in `units`.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct CalibMeta {
    pub(crate) kind: String,
    pub(crate) schema: u32,
    pub(crate) pgrf_version: String,
    /// Camera maker from the frames' metadata.
    pub make: String,
    /// Camera model from the frames' metadata.
    pub model: String,
    /// ISO of the frames (or the one given when files carry none).
    pub iso: Option<u32>,
    /// Frame width in pixels (the maps are packed to half of it).
    pub width: usize,
    /// Frame height in pixels (the maps are packed to half of it).
    pub height: usize,
    pub(crate) cfa: String,
    pub(crate) black: [f32; 4],
    pub(crate) white: u32,
    /// Bias frames averaged.
    pub bias_frames: usize,
    pub(crate) bias_exposure_s: f64,
    /// Exposure times of the dark stack, s (empty without darks).
    pub dark_exposures_s: Vec<f64>,
    /// Dark frames averaged at each of those exposures.
    pub dark_frames: Vec<usize>,
    pub(crate) flat_exposures_s: Vec<f64>,
    pub(crate) flat_frames: Vec<usize>,
    /// System gain K, DN per electron.
    #[serde(rename = "K")]
    pub k: f64,
    /// How `k` was estimated.
    pub k_method: GainMethod,
    /// Row-noise standard deviation sigma_H, DN.
    pub row_sigma: f64,
    /// Standard deviation of the whole-frame offset from frame to frame, DN
    /// (measured on the bias frames, apart from row noise); None in records
    /// older than the measurement.
    #[serde(default)]
    pub frame_offset_sigma: Option<f64>,
    /// Median over pixels of the read-noise sigma (row noise removed), DN,
    /// corrected for the sampling error of the bias frames' number
    /// (records before that correction hold the plain median of the map,
    /// a few per cent low).
    pub read_sigma_median: f64,
    /// EMVA 1288's temporal dark noise sigma_y.dark, DN: from the
    /// differences of bias-frame pairs (row noise and quantisation
    /// included, whole-frame offset drift not); None in older records.
    #[serde(default)]
    pub dark_noise_sigma: Option<f64>,
    /// DSNU: spatial standard deviation of the bias offset, DN.
    pub dsnu: f64,
    /// PRNU: spatial standard deviation of the response divided by its mean
    /// (a fraction, not %); None when not measured.
    pub prnu: Option<f64>,
    /// DSNU the EMVA 1288 way: high-pass filtered (5 x 5 box), outliers
    /// such as hot pixels excluded, DN; None in older records.
    #[serde(default)]
    pub dsnu_highpass: Option<f64>,
    /// PRNU the EMVA 1288 way (high-pass, outliers excluded), a fraction.
    #[serde(default)]
    pub prnu_highpass: Option<f64>,
    /// Standard error of K, DN/e- (statistical only).
    #[serde(default)]
    pub k_sigma: Option<f64>,
    /// EMVA 1288 saturation capacity, electrons (with flats that reach
    /// saturation).
    #[serde(default)]
    pub saturation_capacity_e: Option<f64>,
    /// EMVA 1288 linearity error, a fraction (three flat levels or more
    /// between 5 and 95 % of saturation).
    #[serde(default)]
    pub linearity_error: Option<f64>,
    /// The dark-signal law chosen by the better R^2 of the pixel-averaged
    /// dark signal; "none" in the record without dark frames.
    #[serde(with = "law_or_none")]
    pub dark_law: Option<DarkLaw>,
    /// R^2 of the fit a sqrt(t) to the pixel-averaged dark signal; None
    /// without dark frames.
    pub dark_r2_sqrt: Option<f64>,
    /// R^2 of the fit a t to the pixel-averaged dark signal; None without
    /// dark frames.
    pub dark_r2_linear: Option<f64>,
    /// Mean dark rate, electrons per sqrt(s) (sqrt law) or per s (linear
    /// law); None without dark frames.
    pub dark_rate_mean: Option<f64>,
    /// The unit of `dark_rate_mean` and of the `dark_rate` map: "e-/s"
    /// (linear law) or "e-/sqrt(s)" (sqrt law); None without dark frames
    /// and in records older than the field ([`CalibMeta::dark_rate_unit`]
    /// tells it from the law for those).
    #[serde(default)]
    pub dark_rate_unit: Option<String>,
    /// Whether the dark law has an offset term c (y = a g(t) + c, chosen
    /// per sensor); false in records older than the term.
    #[serde(default)]
    pub dark_offset: bool,
    /// Mean dark offset c, DN (present with `dark_offset`; the per-pixel
    /// values are the `dark_offset` map).
    #[serde(default)]
    pub dark_offset_mean: Option<f64>,
    /// Median over the tapped pixels of the read noise's probability-plot
    /// correlation coefficient with a normal (1 is perfectly Gaussian).
    pub ppcc_pixel_median: Option<f64>,
    pub(crate) ppcc_pooled: Option<f64>,
    /// Median capture temperature of the frames, degrees C, when they record
    /// one (every frame within the run's tolerance of it).
    #[serde(default)]
    pub temperature_c: Option<f32>,
    /// What the estimates could not check (one flat level: no linearity
    /// check of K), as the run printed them.
    #[serde(default)]
    pub warnings: Vec<String>,
    /// Frames dropped with `reject` ([`crate::CalibrateInput::reject`]),
    /// each with why.
    #[serde(default)]
    pub rejected_frames: Vec<String>,
    /// The order the calibration frames stored their rows in (FITS
    /// ROWORDER; TOP-DOWN for camera RAWs): the maps are in it, and a frame
    /// stored the other way up is refused. None in older records.
    #[serde(default)]
    pub row_order: Option<pgrf_raw::RowOrder>,
    /// Number of pixels flagged hot (1 in the `defects` map).
    pub hot_pixels: usize,
    /// Number of pixels flagged dead (2 in the `defects` map).
    pub dead_pixels: usize,
    /// Number of pixels flagged cold (3 in the `defects` map).
    #[serde(default)]
    pub cold_pixels: usize,
    /// Number of defective sensor columns, each counted once (records
    /// before issue 39 counted per packed plane); their pixels are 4 in the
    /// `defects` map where not flagged otherwise.
    #[serde(default)]
    pub defect_columns: usize,
    /// Temperature rise that doubles the dark current, degrees C, fitted to
    /// darks at two or more temperatures ([`crate::temperature`]); None when
    /// not measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dark_doubling_c: Option<f64>,
    /// The dark rates it was fitted to: (temperature in degrees C, DN per
    /// unit of the law's g(t)).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub dark_rates_by_temperature: Vec<(f32, f64)>,
    pub(crate) units: String,
}

impl CalibMeta {
    /// The frames' filter layout: a CFA phase ("RGGB") or "mono".
    pub fn layout(&self) -> &str {
        &self.cfa
    }

    /// The unit of the dark rate: the record's, else (older records) the
    /// one its law implies; None without a law.
    pub fn dark_rate_unit(&self) -> Option<&str> {
        self.dark_rate_unit
            .as_deref()
            .or_else(|| self.dark_law.map(dark_rate_unit))
    }

    /// The record's values that synthesis and restoration rely on: a frame
    /// size that packs, levels with room between black and white, a positive
    /// finite gain, non-negative finite noise figures, a CFA pgrf knows and
    /// exposures that are times. A record failing any of these would write
    /// saturated or black frames (white 0, black 1e9) or divide by zero
    /// (K 0), so it is refused with the field named.
    pub(crate) fn check(&self) -> std::result::Result<(), RecordFault> {
        self.check_frame()?;
        self.check_figures()
    }

    /// The frame's size, CFA and levels.
    fn check_frame(&self) -> std::result::Result<(), RecordFault> {
        const MAX_SIDE: usize = 1 << 16;
        if self.width < 2
            || self.height < 2
            || !self.width.is_multiple_of(2)
            || !self.height.is_multiple_of(2)
            || self.width > MAX_SIDE
            || self.height > MAX_SIDE
        {
            return Err(RecordFault::FrameSize {
                width: self.width,
                height: self.height,
                max: MAX_SIDE,
            });
        }
        if self.cfa != "mono" {
            self.cfa
                .parse::<pgrf_raw::Cfa>()
                .map_err(|_| RecordFault::Cfa(self.cfa.clone()))?;
        }
        if !(1..=65535).contains(&self.white) {
            return Err(RecordFault::White(self.white));
        }
        for &black in &self.black {
            if !(black.is_finite() && black >= 0.0 && (black as f64) < self.white as f64) {
                return Err(RecordFault::Black {
                    black,
                    white: self.white,
                });
            }
        }
        Ok(())
    }

    /// The gain, noise figures, ISO, exposures and dark-signal figures.
    fn check_figures(&self) -> std::result::Result<(), RecordFault> {
        let max = pgrf_noise::profile::MAX_GAIN;
        if !(self.k.is_finite() && self.k > 0.0 && self.k <= max) {
            return Err(RecordFault::Gain { k: self.k, max });
        }
        for (field, value) in [
            ("row_sigma", self.row_sigma),
            ("read_sigma_median", self.read_sigma_median),
            ("dark_noise_sigma", self.dark_noise_sigma.unwrap_or(0.0)),
            ("dsnu", self.dsnu),
            ("bias_exposure_s", self.bias_exposure_s),
        ] {
            // A noise figure or exposure beyond the DN range (or a day) is
            // no sensor's: 1e300 would overflow once squared or scaled.
            if !(value.is_finite() && (0.0..=65535.0).contains(&value)) {
                return Err(RecordFault::Figure { field, value });
            }
        }
        if self.iso == Some(0) {
            return Err(RecordFault::ZeroIso);
        }
        for &t in self.dark_exposures_s.iter().chain(&self.flat_exposures_s) {
            if !(t.is_finite() && (0.0..=1e6).contains(&t)) {
                return Err(RecordFault::Exposure(t));
            }
        }
        if let Some(r) = self.dark_rate_mean {
            if !(r.is_finite() && r.abs() <= 1e9) {
                return Err(RecordFault::DarkRate(r));
            }
        }
        // A light's dark is scaled by 2^(dT / doubling): a doubling of a
        // fraction of a degree (or none) is no sensor's.
        if let Some(d) = self.dark_doubling_c {
            if !(d.is_finite() && (0.5..=100.0).contains(&d)) {
                return Err(RecordFault::Figure {
                    field: "dark_doubling_c",
                    value: d,
                });
            }
        }
        if let Some(c) = self.dark_offset_mean {
            if !(c.is_finite() && c.abs() <= self.white as f64) {
                return Err(RecordFault::DarkOffset(c));
            }
        }
        Ok(())
    }
}

/// The unit of a dark rate under `law`: electrons per second, or per
/// square root of a second.
pub(crate) fn dark_rate_unit(law: DarkLaw) -> &'static str {
    match law {
        DarkLaw::Linear => "e-/s",
        DarkLaw::Sqrt => "e-/sqrt(s)",
    }
}

/// The record writes the law's name, or "none" without dark frames.
mod law_or_none {
    use pgrf_noise::DarkLaw;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    pub(crate) fn serialize<S: Serializer>(law: &Option<DarkLaw>, s: S) -> Result<S::Ok, S::Error> {
        match law {
            Some(l) => l.serialize(s),
            None => s.serialize_str("none"),
        }
    }

    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(
        d: D,
    ) -> Result<Option<DarkLaw>, D::Error> {
        let name = String::deserialize(d)?;
        match name.as_str() {
            "none" => Ok(None),
            "sqrt" => Ok(Some(DarkLaw::Sqrt)),
            "linear" => Ok(Some(DarkLaw::Linear)),
            o => Err(serde::de::Error::custom(format!(
                "unknown dark law '{o}' (sqrt, linear or none)"
            ))),
        }
    }
}

/// A calibration: the per-pixel maps and the record of how they were made,
/// as [`calibrate`](crate::calibrate()) produces them and the file stores them.
#[derive(Clone, Debug)]
pub struct Calibration {
    /// How the calibration was made (camera, ISO, levels, frames, global figures).
    pub meta: CalibMeta,
    /// The per-pixel maps.
    pub maps: CalibMaps,
}

/// The per-pixel maps of a calibration, each packed `(4, H/2, W/2)` in the
/// order R, G1, B, G2 (a monochrome sensor's: its four sub-lattices, in
/// RGGB's order, as [`pgrf_raw::RawFrame::from_mono`] packs them). In the
/// file each is a tensor of the field's name: packed for a colour sensor,
/// for a monochrome one a single plane `(1, H, W)` of the sensor's pixels
/// as they lie ([`Calibration::save`]), which numpy users read without
/// knowing pgrf's packing. Every value is finite.
#[derive(Clone, Debug)]
pub struct CalibMaps {
    /// Bias mean minus black level, DN: the fixed-pattern offset.
    pub fixed_pattern: Array3<f32>,
    /// Temporal read-noise sigma (row noise removed), DN: sigma of N_r.
    pub sigma_read: Array3<f32>,
    /// Dark-current rate, electrons per second or per sqrt(second) after the
    /// record's law (N_FP absorbed); zero without dark frames.
    pub dark_rate: Array3<f32>,
    /// 0 good, 1 hot, 2 dead, 3 cold, 4 in a defective column
    /// (`crate::estimate::defect`).
    pub defects: Array3<f32>,
    /// Per-pixel system gain, DN per electron (eq. 3.15).
    pub gain: Option<Array3<f32>>,
    /// Per-pixel response to light relative to the mean (PRNU).
    pub response: Option<Array3<f32>>,
    /// R^2 of the per-pixel dark fit a*sqrt(t).
    pub r2_sqrt: Option<Array3<f32>>,
    /// R^2 of the per-pixel dark fit a*t.
    pub r2_linear: Option<Array3<f32>>,
    /// Per-pixel offset c of the dark law y = a g(t) + c, DN, when the
    /// record's law has one: dark charge every exposed frame has and a
    /// zero-length bias frame lacks.
    pub dark_offset: Option<Array3<f32>>,
    /// The bias frames' residual noise, DN, packed like the maps or a
    /// centre crop of them (see the `bank` module); in the file `noise_bank_00`,
    /// `noise_bank_01`, ...
    pub noise_bank: Vec<Array3<f32>>,
}

/// The file names of the noise bank's frames, in order.
const BANK_NAMES: [&str; pgrf_noise::bank::MAX_BANK_FRAMES] = [
    "noise_bank_00",
    "noise_bank_01",
    "noise_bank_02",
    "noise_bank_03",
    "noise_bank_04",
    "noise_bank_05",
    "noise_bank_06",
    "noise_bank_07",
];

impl CalibMaps {
    /// Every present map with its file name, in name order.
    pub fn named(&self) -> Vec<(&'static str, &Array3<f32>)> {
        let mut v: Vec<(&'static str, &Array3<f32>)> = vec![
            ("dark_rate", &self.dark_rate),
            ("defects", &self.defects),
            ("fixed_pattern", &self.fixed_pattern),
            ("sigma_read", &self.sigma_read),
        ];
        v.extend(BANK_NAMES.iter().copied().zip(&self.noise_bank));
        for (name, m) in [
            ("dark_offset", &self.dark_offset),
            ("gain", &self.gain),
            ("r2_linear", &self.r2_linear),
            ("r2_sqrt", &self.r2_sqrt),
            ("response", &self.response),
        ] {
            if let Some(m) = m {
                v.push((name, m));
            }
        }
        v.sort_by_key(|(n, _)| *n);
        v
    }

    /// The maps of a file (`path`, for messages), by name: the four
    /// required ones must be there, and a name pgrf does not know is refused.
    fn from_named(mut maps: BTreeMap<String, Array3<f32>>, path: &Path) -> Result<CalibMaps> {
        let mut need = |n: &str| {
            maps.remove(n).ok_or_else(|| CalibError::MissingMap {
                path: path.to_path_buf(),
                map: n.into(),
            })
        };
        let out = CalibMaps {
            fixed_pattern: need("fixed_pattern")?,
            sigma_read: need("sigma_read")?,
            dark_rate: need("dark_rate")?,
            defects: need("defects")?,
            gain: maps.remove("gain"),
            response: maps.remove("response"),
            r2_sqrt: maps.remove("r2_sqrt"),
            r2_linear: maps.remove("r2_linear"),
            dark_offset: maps.remove("dark_offset"),
            noise_bank: BANK_NAMES.iter().map_while(|n| maps.remove(*n)).collect(),
        };
        if let Some(n) = maps.keys().next() {
            return Err(CalibError::UnknownMap {
                path: path.to_path_buf(),
                map: n.clone(),
            });
        }
        Ok(out)
    }
}

/// The Bayer phase whose offsets order a monochrome frame's sub-lattices
/// in the packed planes ([`pgrf_raw::RawFrame::from_mono`]).
const MONO_LATTICES: Cfa = Cfa::Rggb;

/// A packed map `(4, H/2, W/2)` laid out as the sensor's pixels, row by
/// row (`H x W` values): plane p's value (i, j) at photosite (2 i + dy,
/// 2 j + dx), (dy, dx) the plane's offsets under `cfa`.
pub(crate) fn sensor_layout(map: &Array3<f32>, cfa: Cfa) -> Vec<f32> {
    let (_, ph, pw) = map.dim();
    let w = 2 * pw;
    let mut out = vec![0.0f32; 4 * ph * pw];
    for (p, (dy, dx)) in cfa.offsets().into_iter().enumerate() {
        for ((i, j), &v) in map.index_axis(ndarray::Axis(0), p).indexed_iter() {
            out[(2 * i + dy) * w + 2 * j + dx] = v;
        }
    }
    out
}

/// [`sensor_layout`]'s inverse: an `h x w` image (`(1, h, w)`) packed.
fn packed(image: &Array3<f32>, cfa: Cfa) -> Array3<f32> {
    let (_, h, w) = image.dim();
    let offsets = cfa.offsets();
    Array3::from_shape_fn((4, h / 2, w / 2), |(p, i, j)| {
        image[[0, 2 * i + offsets[p].0, 2 * j + offsets[p].1]]
    })
}

impl Calibration {
    /// Write the calibration file at `path` atomically: one safetensors
    /// tensor per map (named as [`CalibMaps::named`]; a monochrome
    /// sensor's as one plane of its pixels, [`CalibMaps`]) and the record
    /// as JSON metadata.
    pub fn save(&self, path: &Path) -> Result<()> {
        let meta = serde_json::to_value(&self.meta).map_err(CalibError::EncodeRecord)?;
        let named = self.maps.named();
        let single: Vec<Array3<f32>> = if self.meta.cfa == "mono" {
            named
                .iter()
                .map(|(_, m)| {
                    // The map's own size: a noise bank's frames may be crops.
                    let (_, ph, pw) = m.dim();
                    Array3::from_shape_vec((1, 2 * ph, 2 * pw), sensor_layout(m, MONO_LATTICES))
                        .expect("a packed map holds H x W values")
                })
                .collect()
        } else {
            Vec::new()
        };
        let views: Vec<(&str, ndarray::ArrayView3<f32>)> = named
            .iter()
            .enumerate()
            .map(|(i, (k, v))| (*k, single.get(i).map_or_else(|| v.view(), |s| s.view())))
            .collect();
        write_maps(path, &views, &meta)?;
        Ok(())
    }

    /// Read a calibration file, refusing files that are not pgrf
    /// calibrations, maps whose shape disagrees with the record, unknown maps
    /// and invalid values.
    pub fn load(path: &Path) -> Result<Calibration> {
        let bytes = std::fs::read(path).map_err(|error| CalibError::Read {
            path: path.to_path_buf(),
            error,
        })?;
        Calibration::from_bytes(&bytes, path)
    }

    /// [`Calibration::load`] on bytes in memory; `path` only names the source
    /// in messages. Every record value a later step divides by, scales with or
    /// allocates from is checked here, where the file enters, so a hostile
    /// file is one error and never a panic or a silently wrong frame.
    pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<Calibration> {
        let (meta, maps) = pgrf_noise::mapfile::decode_maps(bytes, path)?;
        if meta.get("kind").and_then(|k| k.as_str()) != Some("pgrf-calibration") {
            return Err(CalibError::NotCalibration {
                path: path.to_path_buf(),
            });
        }
        let bad_record = |fault| CalibError::BadRecord {
            path: path.to_path_buf(),
            fault,
        };
        let meta: CalibMeta =
            serde_json::from_value(meta).map_err(|e| bad_record(RecordFault::Json(e)))?;
        meta.check().map_err(bad_record)?;
        let shape = [4, meta.height / 2, meta.width / 2];
        // A monochrome sensor's maps are one plane of its pixels (records
        // before that: packed, still read).
        let mono = meta.cfa == "mono";
        let single = [1, meta.height, meta.width];
        let mut maps = maps;
        for (name, a) in maps.iter_mut() {
            // A noise bank's frames may be a centre crop of the maps.
            let crop = name.starts_with("noise_bank_");
            let fits = |found: &[usize], full: [usize; 3]| match crop {
                false => found == full,
                true => {
                    found.len() == 3
                        && found[0] == full[0]
                        && (1..=full[1]).contains(&found[1])
                        && (1..=full[2]).contains(&found[2])
                        && (full[0] == 4
                            || (found[1].is_multiple_of(2) && found[2].is_multiple_of(2)))
                }
            };
            if mono && fits(a.shape(), single) {
                *a = packed(a, MONO_LATTICES);
            } else if !fits(a.shape(), shape) {
                return Err(CalibError::MapShape {
                    path: path.to_path_buf(),
                    map: name.clone(),
                    shape: a.shape().to_vec(),
                    expected: if mono { single } else { shape },
                });
            }
        }
        let maps = CalibMaps::from_named(maps, path)?;
        let c = Calibration { meta, maps };
        if !c.maps.noise_bank.is_empty() {
            pgrf_noise::bank::NoiseBank::check(&c.maps.noise_bank).map_err(|error| {
                CalibError::MapValues {
                    path: path.to_path_buf(),
                    error,
                }
            })?;
        }
        c.to_pixel_maps()?
            .check_values()
            .map_err(|error| CalibError::MapValues {
                path: path.to_path_buf(),
                error,
            })?;
        Ok(c)
    }

    /// The noise bank of the calibration's bias frames, None when it has
    /// none (fewer than two bias frames, or a file from before banks).
    pub fn bank(
        &self,
    ) -> Option<std::result::Result<pgrf_noise::bank::NoiseBank, pgrf_noise::NoiseError>> {
        let frames = &self.maps.noise_bank;
        (!frames.is_empty()).then(|| pgrf_noise::bank::NoiseBank::new(frames.clone()))
    }

    /// Refuse to apply a calibration of another camera or ISO (unless forced).
    pub fn check_matches(
        &self,
        make: &str,
        model: &str,
        iso: Option<u32>,
        force: bool,
    ) -> Result<()> {
        if force {
            return Ok(());
        }
        let m = &self.meta;
        if (m.make.as_str(), m.model.as_str()) != (make, model) {
            return Err(CalibError::WrongCamera {
                calibration: format!("{} {}", m.make, m.model),
                frame: format!("{make} {model}"),
            });
        }
        if m.iso.is_some() && iso.is_some() && m.iso != iso {
            return Err(CalibError::WrongIso {
                calibration: m.iso.unwrap_or(0),
                frame: iso.unwrap_or(0),
            });
        }
        Ok(())
    }

    /// Refuse a frame whose filter layout (CFA phase, or "mono") or stored
    /// row order differs from the calibration's: the per-pixel maps are
    /// stored by packed plane and row, so another phase or a flipped frame
    /// would put every map on the wrong photosites. Not overridable, unlike
    /// the camera check.
    pub fn check_layout(&self, frame: &pgrf_raw::RawFrame) -> Result<()> {
        if self.meta.cfa != frame.layout() {
            return Err(CalibError::WrongLayout {
                calibration: self.meta.cfa.clone(),
                frame: frame.layout().into(),
            });
        }
        if let Some(rows) = self.meta.row_order.filter(|&r| r != frame.row_order()) {
            return Err(CalibError::WrongRowOrder {
                calibration: rows.keyword(),
                frame: frame.row_order().keyword(),
            });
        }
        Ok(())
    }

    /// The noise model's per-pixel maps. N_FP is not separated from the dark
    /// rate by this calibration (it is absorbed in it), so it is zero. A
    /// dark law's offset c is in every exposed frame, so it joins the fixed
    /// pattern: synthesis always simulates an exposure.
    pub fn to_pixel_maps(&self) -> Result<PixelMaps> {
        let pixel = |a: &Array3<f32>| Map::Pixel(Arc::new(a.clone()));
        let law = self.meta.dark_law.unwrap_or(DarkLaw::Sqrt);
        let bias = match &self.maps.dark_offset {
            Some(c) => &self.maps.fixed_pattern + c,
            None => self.maps.fixed_pattern.clone(),
        };
        Ok(PixelMaps {
            bias: pixel(&bias),
            sigma_read: pixel(&self.maps.sigma_read),
            dark_rate: pixel(&self.maps.dark_rate),
            n_fp: Map::Scalar(0.0),
            dark_law: law,
        })
    }

    /// Make `spec` synthesise this sensor: its per-pixel maps, and the gain,
    /// row noise and DN scale they were measured with (maps are meaningless
    /// on another scale). The ISO is taken from the calibration when unset.
    pub fn apply_to(&self, spec: &mut pgrf_noise::pair::PairSpec) -> Result<()> {
        if spec.kind != pgrf_noise::ModelKind::Pgrf {
            return Err(CalibError::WrongModel { kind: spec.kind });
        }
        let m = &self.meta;
        let black = m.black.iter().map(|&b| b as f64).sum::<f64>() / 4.0;
        spec.maps = Some(self.to_pixel_maps()?);
        spec.measured = Some(pgrf_noise::pair::Measured {
            k: m.k,
            row_sigma: m.row_sigma,
            dn_range: m.white as f64 - black,
            black,
        });
        if spec.iso.is_none() {
            spec.iso = m.iso;
        }
        Ok(())
    }

    /// Expected dark level above black in DN per packed pixel for an exposure
    /// of `exposure_s`: the fixed pattern plus the mean dark current
    /// (rate x law(t) electrons x K DN per electron, plus the law's offset
    /// for an exposed frame, t > 0). This is what dark-frame
    /// subtraction removes before a photo is amplified; the random part of
    /// the dark signal stays for the denoiser.
    pub fn dark_shading_dn(&self, exposure_s: f64) -> Result<Array3<f32>> {
        if !(exposure_s.is_finite() && exposure_s >= 0.0) {
            return Err(CalibError::BadExposure { exposure_s });
        }
        let law = self.meta.dark_law.unwrap_or(DarkLaw::Sqrt);
        let dn_per_rate = law.electrons(1.0, exposure_s) * self.meta.k;
        let mut out = self.maps.fixed_pattern.clone();
        ndarray::Zip::from(&mut out)
            .and(&self.maps.dark_rate)
            .for_each(|o, &r| *o += (r as f64 * dn_per_rate) as f32);
        if let (Some(c), true) = (&self.maps.dark_offset, exposure_s > 0.0) {
            out += c;
        }
        Ok(out)
    }

    /// Cosmetic correction, as astro software applies it after dark
    /// subtraction: every pixel the defect map flags hot, dead or cold is
    /// replaced by the median of its eight nearest neighbours of the same
    /// plane that are not flagged, so a hot pixel's shot noise, which no
    /// dark frame removes, is not handed to the denoiser. In a Bayer mosaic
    /// the same colour sits two photosites away; a monochrome sensor has
    /// one colour, so its direct neighbours, half as far and sampling the
    /// scene where the defect is, replace it. Defective columns (a
    /// column's response to light, issue 54) are left to the network here;
    /// `pgrf reduce` replaces them after the flat. Returns how many pixels were
    /// replaced; `frame` must be the calibration's size (checked by the
    /// caller with the rest of the calibration).
    pub fn correct_defects(&self, frame: &mut pgrf_raw::RawFrame) -> usize {
        let d = &self.maps.defects;
        let (_, ph, pw) = d.dim();
        let (h, w) = (frame.height, frame.width);
        if (2 * ph, 2 * pw) != (h, w) {
            return 0;
        }
        let cfa = frame.cfa;
        let replaced = |v: f32| v == defect::HOT || v == defect::DEAD || v == defect::COLD;
        let flagged = |r: usize, c: usize| replaced(d[[cfa.plane_at(r, c), r / 2, c / 2]]);
        let step: isize = if frame.mono { 1 } else { 2 };
        let mut fixed = 0;
        for (p, (dy, dx)) in cfa.offsets().into_iter().enumerate() {
            let plane = d.index_axis(ndarray::Axis(0), p);
            for ((i, j), &v) in plane.indexed_iter() {
                if !replaced(v) {
                    continue;
                }
                let (r, c) = (2 * i + dy, 2 * j + dx);
                let mut near: Vec<u16> = Vec::with_capacity(8);
                for (di, dj) in [
                    (-1, -1),
                    (-1, 0),
                    (-1, 1),
                    (0, -1),
                    (0, 1),
                    (1, -1),
                    (1, 0),
                    (1, 1),
                ] {
                    let (nr, nc) = (r as isize + step * di, c as isize + step * dj);
                    if nr < 0 || nc < 0 || nr >= h as isize || nc >= w as isize {
                        continue;
                    }
                    let (nr, nc) = (nr as usize, nc as usize);
                    if !flagged(nr, nc) {
                        near.push(frame.mosaic[nr * w + nc]);
                    }
                }
                if near.is_empty() {
                    continue;
                }
                near.sort_unstable();
                let n = near.len();
                let med = if n % 2 == 1 {
                    near[n / 2]
                } else {
                    (near[n / 2 - 1] as u32 + near[n / 2] as u32).div_ceil(2) as u16
                };
                frame.mosaic[r * w + c] = med;
                fixed += 1;
            }
        }
        fixed
    }

    /// A short identity for records: camera, ISO and file name.
    pub fn identity(&self, path: &Path) -> String {
        format!(
            "{} {} ISO {} ({})",
            self.meta.make,
            self.meta.model,
            self.meta
                .iso
                .map(|i| i.to_string())
                .unwrap_or_else(|| "?".into()),
            path.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default()
        )
    }
}
