//! Light-frame reduction, the astrophotographer's last calibration step
//! (what `pgrf reduce` runs): each light frame becomes
//!
//! ```text
//! (light - master bias - dark(t)) / flat
//! dark(t) = c + (master dark - master bias - c) * g(t) / g(t_d)
//! flat    = (master flat - master bias - dark(t_f)), divided by its mean
//!           per packed plane (R, G1, B, G2; one mean for a monochrome sensor)
//! ```
//!
//! with `g` the calibration's dark law (`t` or `sqrt(t)`), `c` its dark
//! offset map when the law has one (else 0), `t_d` the exposure of the
//! master dark nearest the light's in ratio, then the calibration's
//! defective pixels replaced by the median of their same-colour neighbours.
//! The masters are the folder `pgrf calibrate --masters DIR` writes, read
//! unrounded (FITS masters are 32-bit floats); the calibration file gives
//! the dark law, the offset, the defect map and what lights must match.
//! Every light is checked against the masters (size, filter layout, row
//! order, camera, ISO, temperature, exposure within the darks' range)
//! before any is reduced, so a refusal names its file and nothing is
//! written.

use crate::calibrate::law_name;
use crate::calibration::sensor_layout;
use crate::error::CalibError;
use crate::Calibration;
use pgrf_core::paths::check_outputs;
use pgrf_core::Progress;
use pgrf_noise::DarkLaw;
use pgrf_raw::fits::{FitsCard, FitsValue};
use pgrf_raw::{decode_file, LevelOverrides, RawError, RawFrame};
use std::path::{Path, PathBuf};

/// A reduction run: the lights, the masters and the calibration they are
/// reduced with, and where the results go.
#[derive(Clone, Debug, Default)]
pub struct ReduceConfig {
    /// Light frames (FITS or camera RAW), or folders of them (their files,
    /// sorted by name).
    pub lights: Vec<PathBuf>,
    /// The masters folder `pgrf calibrate --masters` wrote: `master_bias`,
    /// `master_dark_<t>s` (any number), `master_flat_<t>s` (the brightest
    /// is used), each `.fits` or `.dng`.
    pub masters: PathBuf,
    /// The calibration file of the same run: dark law, dark offset,
    /// defect map, temperature, camera.
    pub calib: PathBuf,
    /// Output folder (created if missing): one file per light, its name
    /// kept but for the final extension, FITS for a FITS light and DNG for
    /// a camera RAW.
    pub output: PathBuf,
    /// How far (degrees C) a light's temperature may lie from the
    /// calibration's; None for [`crate::calibrate::TEMPERATURE_TOLERANCE_C`].
    pub temperature_tolerance: Option<f32>,
}

/// Why lights could not be reduced; each names the file at fault.
#[derive(Debug, thiserror::Error)]
pub enum ReduceError {
    /// The calibration file, a master or a light could not be read, or an
    /// output not written.
    #[error(transparent)]
    Calib(Box<CalibError>),
    /// A frame could not be decoded (the decoder names the file).
    #[error(transparent)]
    Raw(#[from] RawError),
    /// A master could not be read a second time (for its unrounded samples).
    #[error("{}: cannot read: {source}", file.display())]
    Read {
        /// The master.
        file: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The masters folder could not be listed.
    #[error("{}: cannot list the masters folder: {source}", dir.display())]
    ListMasters {
        /// The folder.
        dir: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// A master the reduction needs is not in the folder.
    #[error("{}: no {what} in the masters folder (the folder `pgrf calibrate --masters DIR` writes)", dir.display())]
    MissingMaster {
        /// The folder.
        dir: PathBuf,
        /// "master_bias.fits or master_bias.dng", ...
        what: &'static str,
    },
    /// A master dark or flat without an exposure time.
    #[error("{}: no exposure time in the master's metadata (darks are scaled by it)", file.display())]
    MasterExposure {
        /// The master.
        file: PathBuf,
    },
    /// Master darks but a calibration without a dark law to scale them.
    #[error("{}: the calibration has no dark law (made without darks), but the masters folder holds master darks: use the calibration file of the same run", calib.display())]
    NoDarkLaw {
        /// The calibration file.
        calib: PathBuf,
    },
    /// A frame (light or master) whose size or layout is not the
    /// calibration's.
    #[error("{}: {what} {found}, the masters' {expected}", file.display())]
    Mismatch {
        /// The frame.
        file: PathBuf,
        /// "size", "filter layout", "binning".
        what: &'static str,
        /// The masters' value.
        expected: String,
        /// The frame's value.
        found: String,
    },
    /// A frame the calibration refuses (another camera, ISO, filter layout
    /// or row order).
    #[error("{}: {source}", file.display())]
    Refused {
        /// The frame.
        file: PathBuf,
        /// The calibration's refusal.
        source: Box<CalibError>,
    },
    /// A light without an exposure time, with darks to scale to it.
    #[error("{}: no exposure time in the light's metadata; the master darks are scaled to it", file.display())]
    NoExposure {
        /// The light.
        file: PathBuf,
    },
    /// A light whose exposure the master darks do not cover: scaling a
    /// dark beyond the exposures it was measured at extrapolates the law.
    #[error("{}: exposure {} s lies outside the master darks' {} .. {} s; shoot darks that bracket the lights' exposure", file.display(), *.exposure_s as f32, *.lo as f32, *.hi as f32)]
    Exposure {
        /// The light.
        file: PathBuf,
        /// Its exposure, s.
        exposure_s: f64,
        /// The shortest master dark's exposure, s.
        lo: f64,
        /// The longest master dark's exposure, s.
        hi: f64,
    },
    /// A light taken further from the calibration's temperature than
    /// allowed: dark current doubles every 5-7 degrees.
    #[error("{}: taken at {light_c:.1} °C, the calibration at {calib_c:.1} °C; more than {tolerance} °C apart the darks do not fit (dark current doubles every 5-7 °C): allow more with --temperature-tolerance", file.display())]
    Temperature {
        /// The light.
        file: PathBuf,
        /// Its temperature, degrees C.
        light_c: f32,
        /// The calibration's (median of its frames), degrees C.
        calib_c: f32,
        /// The allowed distance, degrees C.
        tolerance: f32,
    },
    /// A light farther from the calibration's temperature than its dark is
    /// scaled over by the measured doubling temperature.
    #[error("{}: taken at {light_c:.1} °C, the calibration at {calib_c:.1} °C: its dark (doubling every {doubling:.1} °C) is scaled over {reach} °C at most", file.display())]
    TemperatureBeyondScale {
        /// The light.
        file: PathBuf,
        /// Its temperature, degrees C.
        light_c: f32,
        /// The calibration's, degrees C.
        calib_c: f32,
        /// The largest distance scaled over, degrees C.
        reach: f32,
        /// The calibration's doubling temperature, degrees C.
        doubling: f64,
    },
    /// A master flat whose plane has no light once bias and dark are off.
    #[error("{}: plane {plane} averages {mean} DN above bias and dark: not a flat field", file.display())]
    DarkFlat {
        /// The master flat.
        file: PathBuf,
        /// The packed plane (R, G1, B, G2 or 0 for mono).
        plane: usize,
        /// Its mean, DN.
        mean: f64,
    },
    /// Two lights whose results would be one file.
    #[error("{}: both {} and {} would be reduced into it (one name per light)", output.display(), first.display(), second.display())]
    SameOutput {
        /// The output.
        output: PathBuf,
        /// The first light.
        first: PathBuf,
        /// The second.
        second: PathBuf,
    },
    /// The output folder could not be made or an output not written.
    #[error("{}: cannot write: {reason}", path.display())]
    Write {
        /// The file or folder.
        path: PathBuf,
        /// Why, on one line.
        reason: String,
    },
}

impl From<CalibError> for ReduceError {
    fn from(e: CalibError) -> Self {
        ReduceError::Calib(Box::new(e))
    }
}

/// One master frame: its file, exposure and samples in DN (black included),
/// row by row as stored.
#[derive(Clone, Debug)]
pub struct MasterFrame {
    /// The file.
    pub path: PathBuf,
    /// Its exposure, s (0 for a bias without one).
    pub exposure_s: f64,
    /// The samples, DN, unrounded for FITS masters.
    pub samples: Vec<f32>,
}

impl MasterFrame {
    /// The file name, for header cards and messages.
    pub fn name(&self) -> String {
        self.path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    }
}

/// The masters a reduction uses, with what the calibration adds.
#[derive(Clone, Debug)]
pub struct Masters {
    /// The master bias.
    pub bias: MasterFrame,
    /// The master darks, by exposure (empty: no dark subtracted).
    pub darks: Vec<MasterFrame>,
    /// The master flat used (the brightest above bias).
    pub flat: MasterFrame,
    /// The flat ready to divide by: bias and dark off, mean 1 per plane.
    pub flat_norm: Vec<f32>,
    /// The flat's mean per plane before normalising, DN.
    pub flat_means: Vec<f64>,
    /// The calibration's dark law (None without darks).
    pub law: Option<DarkLaw>,
    /// The dark offset c per pixel, DN, when the law has one.
    pub offset: Option<Vec<f32>>,
    /// Defective pixels of the calibration's map, sensor layout.
    pub defective: Vec<bool>,
    /// Frame width and height.
    pub size: (usize, usize),
    /// Monochrome sensor (one flat mean, neighbours at step 1).
    pub mono: bool,
    /// The CFA phase of stored pixel (0, 0).
    pub cfa: pgrf_raw::Cfa,
    /// The master bias's XBINNING x YBINNING, when its header states one.
    pub binning: Option<(u32, u32)>,
    /// The calibration's temperature and the doubling temperature of its
    /// dark current, degrees C, when both were measured: a light's dark is
    /// scaled to the light's temperature ([`Masters::temperature_scale`]).
    pub dark_temperature: Option<(f32, f64)>,
}

/// The time factor of `law`: g(t) in dark(t) = a g(t) + c.
fn time_factor(law: DarkLaw, t: f64) -> f64 {
    match law {
        DarkLaw::Linear => t.max(0.0),
        DarkLaw::Sqrt => t.max(0.0).sqrt(),
    }
}

impl Masters {
    /// The master dark for exposure `t`: the one nearest in ratio
    /// (|ln(t / t_d)| smallest; a tie goes to the longer, whose dark signal
    /// stands further above its noise), with the factor g(t) / g(t_d) that
    /// scales it. None without darks.
    pub fn dark_for(&self, t: f64) -> Option<(&MasterFrame, f64)> {
        let law = self.law?;
        let d = self.darks.iter().min_by(|a, b| {
            let r = |m: &MasterFrame| (t.max(1e-12) / m.exposure_s.max(1e-12)).ln().abs();
            r(a).total_cmp(&r(b))
                .then(b.exposure_s.total_cmp(&a.exposure_s))
        })?;
        let g = time_factor(law, d.exposure_s);
        let scale = if g > 0.0 {
            time_factor(law, t) / g
        } else {
            0.0
        };
        Some((d, scale))
    }

    /// The dark signal at exposure `t`, DN per pixel (zeros without darks):
    /// c + (dark - bias - c) * scale, times `temperature` (the dark's factor
    /// to a light's temperature, [`Masters::temperature_scale`]; 1 for
    /// none).
    fn dark_signal(&self, t: f64, temperature: f64) -> Vec<f32> {
        let n = self.bias.samples.len();
        let Some((d, scale)) = self.dark_for(t) else {
            return vec![0.0; n];
        };
        let (scale, temperature) = (scale as f32, temperature as f32);
        (0..n)
            .map(|i| {
                let c = self.offset.as_ref().map_or(0.0, |o| o[i]);
                (c + (d.samples[i] - self.bias.samples[i] - c) * scale) * temperature
            })
            .collect()
    }

    /// How many times the calibration's the dark current is at a light's
    /// temperature `light_c`: 2^((light - calibration) / doubling); None
    /// without a measured doubling temperature or the light's temperature.
    pub fn temperature_scale(&self, light_c: Option<f32>) -> Option<f64> {
        let (calib_c, doubling) = self.dark_temperature?;
        Some(2f64.powf((light_c? - calib_c) as f64 / doubling))
    }

    /// The packed plane of stored pixel `i` for the flat's means: 0..4,
    /// or 0 for every pixel of a monochrome sensor.
    fn plane(&self, i: usize) -> usize {
        if self.mono {
            0
        } else {
            let w = self.size.0;
            self.cfa.plane_at(i / w, i % w)
        }
    }
}

/// Read one master (FITS unrounded, DNG as its integers).
fn read_master(path: &Path) -> Result<(MasterFrame, RawFrame), ReduceError> {
    let frame = decode_file(path, &LevelOverrides::default())?;
    let samples = if frame.fits.is_some() {
        let bytes = std::fs::read(path).map_err(|source| ReduceError::Read {
            file: path.to_path_buf(),
            source,
        })?;
        pgrf_raw::fits::read_fits_samples(path, &bytes)?.1
    } else {
        frame.mosaic.iter().map(|&v| f32::from(v)).collect()
    };
    Ok((
        MasterFrame {
            path: path.to_path_buf(),
            exposure_s: frame.exposure_s.unwrap_or(0.0),
            samples,
        },
        frame,
    ))
}

/// Check a frame (light or master) against the calibration: camera, ISO,
/// filter layout, row order and size.
fn check_frame(calib: &Calibration, frame: &RawFrame, file: &Path) -> Result<(), ReduceError> {
    let m = &calib.meta;
    if (m.width, m.height) != (frame.width, frame.height) {
        return Err(ReduceError::Mismatch {
            file: file.to_path_buf(),
            what: "size",
            expected: format!("{}x{}", m.width, m.height),
            found: format!("{}x{}", frame.width, frame.height),
        });
    }
    calib
        .check_matches(&frame.make, &frame.model, frame.iso, false)
        .and_then(|()| calib.check_layout(frame))
        .map_err(|source| ReduceError::Refused {
            file: file.to_path_buf(),
            source: Box::new(source),
        })
}

/// The masters of `dir` with `calib`'s dark law, offset and defects: the
/// bias, every dark, and the brightest flat made ready to divide by.
pub fn load_masters(
    dir: &Path,
    calib: &Calibration,
    calib_path: &Path,
) -> Result<Masters, ReduceError> {
    let files = MasterFiles::list(dir)?;
    let bias_path = files
        .all
        .iter()
        .find(|p| is_frame(p) && stem(p) == "master_bias")
        .ok_or_else(|| files.missing("master_bias.fits or master_bias.dng"))?;
    let (bias, bias_frame) = read_master(bias_path)?;
    check_frame(calib, &bias_frame, bias_path)?;
    let read_timed = |p: &PathBuf| -> Result<MasterFrame, ReduceError> {
        let (m, f) = read_master(p)?;
        check_frame(calib, &f, p)?;
        if f.exposure_s.is_none() {
            return Err(ReduceError::MasterExposure { file: p.clone() });
        }
        Ok(m)
    };
    let mut darks = files
        .of_kind("master_dark_")
        .iter()
        .map(read_timed)
        .collect::<Result<Vec<_>, _>>()?;
    darks.sort_by(|a, b| a.exposure_s.total_cmp(&b.exposure_s));
    let law = if darks.is_empty() {
        None
    } else {
        Some(calib.meta.dark_law.ok_or_else(|| ReduceError::NoDarkLaw {
            calib: calib_path.to_path_buf(),
        })?)
    };
    let flats = files
        .of_kind("master_flat_")
        .iter()
        .map(read_timed)
        .collect::<Result<Vec<_>, _>>()?;
    let above_bias = |f: &MasterFrame| {
        f.samples
            .iter()
            .zip(&bias.samples)
            .map(|(&a, &b)| f64::from(a - b))
            .sum::<f64>()
    };
    let flat = flats
        .into_iter()
        .max_by(|a, b| above_bias(a).total_cmp(&above_bias(b)))
        .ok_or_else(|| files.missing("master_flat_<t>s.fits or .dng"))?;
    let mut masters = assemble(calib, bias, &bias_frame, darks, flat, law);
    normalise_flat(&mut masters)?;
    Ok(masters)
}

/// The files of a masters folder, sorted.
struct MasterFiles<'a> {
    dir: &'a Path,
    all: Vec<PathBuf>,
}

impl<'a> MasterFiles<'a> {
    fn list(dir: &'a Path) -> Result<Self, ReduceError> {
        let list = |source| ReduceError::ListMasters {
            dir: dir.to_path_buf(),
            source,
        };
        let mut all: Vec<PathBuf> = std::fs::read_dir(dir)
            .map_err(list)?
            .map(|e| e.map(|e| e.path()))
            .collect::<Result<_, _>>()
            .map_err(list)?;
        all.sort();
        Ok(MasterFiles { dir, all })
    }

    /// The frames whose name starts with `prefix`.
    fn of_kind(&self, prefix: &str) -> Vec<PathBuf> {
        (self.all.iter())
            .filter(|p| is_frame(p) && stem(p).starts_with(prefix))
            .cloned()
            .collect()
    }

    fn missing(&self, what: &'static str) -> ReduceError {
        ReduceError::MissingMaster {
            dir: self.dir.to_path_buf(),
            what,
        }
    }
}

/// A FITS or DNG file, by its extension.
fn is_frame(p: &Path) -> bool {
    p.extension().and_then(|e| e.to_str()).is_some_and(|e| {
        matches!(
            e.to_ascii_lowercase().as_str(),
            "fits" | "fit" | "fts" | "dng"
        )
    })
}

/// The file name without its extension.
fn stem(p: &Path) -> String {
    p.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// The masters with the calibration's dark offset (when its law has one)
/// and defects in the frames' layout; the flat not yet normalised.
fn assemble(
    calib: &Calibration,
    bias: MasterFrame,
    bias_frame: &RawFrame,
    darks: Vec<MasterFrame>,
    flat: MasterFrame,
    law: Option<DarkLaw>,
) -> Masters {
    let maps = &calib.maps;
    let cfa = bias_frame.cfa;
    let offset = match (&maps.dark_offset, calib.meta.dark_offset, law) {
        (Some(c), true, Some(_)) => Some(sensor_layout(c, cfa)),
        _ => None,
    };
    let defective = sensor_layout(&maps.defects, cfa)
        .into_iter()
        .map(|d| d != 0.0)
        .collect();
    Masters {
        bias,
        darks,
        flat,
        flat_norm: Vec::new(),
        flat_means: Vec::new(),
        law,
        offset,
        defective,
        size: (bias_frame.width, bias_frame.height),
        mono: bias_frame.mono,
        cfa,
        binning: bias_frame.fits.as_ref().and_then(|h| h.binning),
        dark_temperature: calib.meta.temperature_c.zip(calib.meta.dark_doubling_c),
    }
}

/// The flat with bias and dark off, divided by its mean per plane.
fn normalise_flat(m: &mut Masters) -> Result<(), ReduceError> {
    let dark = m.dark_signal(m.flat.exposure_s, 1.0);
    let flat: Vec<f32> = (m.flat.samples.iter().zip(&m.bias.samples).zip(&dark))
        .map(|((&f, &b), &d)| f - b - d)
        .collect();
    let planes = if m.mono { 1 } else { 4 };
    let (mut sum, mut count) = (vec![0.0f64; planes], vec![0usize; planes]);
    for (i, &v) in flat.iter().enumerate() {
        let p = m.plane(i);
        sum[p] += f64::from(v);
        count[p] += 1;
    }
    let means: Vec<f64> = sum
        .iter()
        .zip(&count)
        .map(|(s, &n)| s / n.max(1) as f64)
        .collect();
    for (plane, &mean) in means.iter().enumerate() {
        if mean.is_nan() || mean <= 0.0 {
            return Err(ReduceError::DarkFlat {
                file: m.flat.path.clone(),
                plane,
                mean,
            });
        }
    }
    m.flat_norm = flat
        .iter()
        .enumerate()
        .map(|(i, &v)| (f64::from(v) / means[m.plane(i)]) as f32)
        .collect();
    m.flat_means = means;
    Ok(())
}

/// The master dark a light was given and how it was scaled.
#[derive(Clone, Debug, serde::Serialize)]
pub struct DarkUsed {
    /// The master dark's file name.
    pub master: String,
    /// Its scale factor g(t) / g(t_d) (the dark law at the light's and the
    /// master's exposures).
    pub scale: f64,
    /// The further factor to the light's temperature, when the calibration
    /// measured a doubling temperature ([`Masters::temperature_scale`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub temperature_scale: Option<f64>,
}

/// What became of one light.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ReducedLight {
    /// The light.
    pub input: PathBuf,
    /// The reduced frame's file.
    pub output: PathBuf,
    /// Its exposure, s.
    pub exposure_s: Option<f64>,
    /// The master dark used and its scale.
    pub dark: Option<DarkUsed>,
    /// What cosmetic correction did.
    pub cosmetic: Cosmetic,
}

/// What a run did (`pgrf reduce --json` prints it).
#[derive(Clone, Debug, serde::Serialize)]
pub struct ReduceOutcome {
    /// Each light, in order.
    pub lights: Vec<ReducedLight>,
    /// The master bias's file name.
    pub bias: String,
    /// The master flat's file name.
    pub flat: String,
    /// The dark law ("linear", "sqrt", "none").
    pub law: &'static str,
}

/// Check a light against the calibration and masters: size, layout, row
/// order, camera, ISO, temperature and (with darks) exposure.
fn check_light(
    config: &ReduceConfig,
    calib: &Calibration,
    masters: &Masters,
    file: &Path,
    frame: &RawFrame,
) -> Result<(), ReduceError> {
    check_frame(calib, frame, file)?;
    // A header without XBINNING/YBINNING is taken as unbinned.
    let light_binning = frame.fits.as_ref().and_then(|h| h.binning);
    if light_binning.unwrap_or((1, 1)) != masters.binning.unwrap_or((1, 1)) {
        return Err(ReduceError::Mismatch {
            file: file.to_path_buf(),
            what: "binning",
            expected: crate::stack::binning_name(masters.binning),
            found: crate::stack::binning_name(light_binning),
        });
    }
    let tolerance = config
        .temperature_tolerance
        .unwrap_or(crate::calibrate::TEMPERATURE_TOLERANCE_C);
    // With a measured doubling temperature the dark is scaled to the
    // light's temperature, over a stated range.
    let scaled = masters.dark_temperature.map(|(_, d)| d);
    let reach = match scaled {
        Some(_) => tolerance.max(crate::temperature::DARK_SCALE_RANGE_C),
        None => tolerance,
    };
    if let (Some(light_c), Some(calib_c)) = (frame.temperature_c, calib.meta.temperature_c) {
        if (light_c - calib_c).abs() > reach {
            return Err(match scaled {
                Some(doubling) => ReduceError::TemperatureBeyondScale {
                    file: file.to_path_buf(),
                    light_c,
                    calib_c,
                    reach,
                    doubling,
                },
                None => ReduceError::Temperature {
                    file: file.to_path_buf(),
                    light_c,
                    calib_c,
                    tolerance,
                },
            });
        }
    }
    if let (Some(first), Some(last)) = (masters.darks.first(), masters.darks.last()) {
        let t = frame.exposure_s.ok_or_else(|| ReduceError::NoExposure {
            file: file.to_path_buf(),
        })?;
        let (lo, hi) = (first.exposure_s, last.exposure_s);
        if t < lo * (1.0 - 1e-6) || t > hi * (1.0 + 1e-6) {
            return Err(ReduceError::Exposure {
                file: file.to_path_buf(),
                exposure_s: t,
                lo,
                hi,
            });
        }
    }
    Ok(())
}

/// What cosmetic correction did to a frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Cosmetic {
    /// Defective pixels replaced, in all.
    pub replaced: usize,
    /// Of those, pixels with no good same-colour neighbour in their 3 x 3
    /// ring (a sensor's edge columns, a defective column's neighbour at the
    /// edge), filled from the nearest good ones along their row.
    pub along_row: usize,
    /// Defective pixels whose whole row holds no good pixel of their
    /// colour: kept (0 where not finite).
    pub kept: usize,
}

/// Replace each defective pixel by the median of its non-defective
/// neighbours of the same colour (the 3 x 3 ring at `step` pixels: 2 on a
/// Bayer mosaic, 1 on a monochrome sensor); one without any takes the mean
/// of the nearest good same-colour pixels to its left and right along its
/// row; one whose row has none is kept, or 0 when it is not
/// finite (a pixel the flat does not reach).
pub fn replace_defects(
    data: &mut [f32],
    width: usize,
    defective: &[bool],
    step: usize,
) -> Cosmetic {
    let height = data.len() / width.max(1);
    let mut done = Cosmetic::default();
    let mut near = Vec::with_capacity(8);
    for i in (0..data.len()).filter(|&i| defective[i]) {
        let (y, x) = ((i / width) as isize, (i % width) as isize);
        near.clear();
        for dy in -1isize..=1 {
            for dx in -1isize..=1 {
                let (ny, nx) = (y + dy * step as isize, x + dx * step as isize);
                if (dy, dx) == (0, 0)
                    || ny < 0
                    || nx < 0
                    || ny >= height as isize
                    || nx >= width as isize
                {
                    continue;
                }
                let j = ny as usize * width + nx as usize;
                if !defective[j] {
                    near.push(data[j]);
                }
            }
        }
        if near.is_empty() {
            match along_row(data, width, defective, i, step) {
                Some(v) => {
                    data[i] = v;
                    done.along_row += 1;
                    done.replaced += 1;
                }
                None => {
                    if !data[i].is_finite() {
                        data[i] = 0.0;
                    }
                    done.kept += 1;
                }
            }
            continue;
        }
        near.sort_by(f32::total_cmp);
        let n = near.len();
        data[i] = if n % 2 == 1 {
            near[n / 2]
        } else {
            (near[n / 2 - 1] + near[n / 2]) / 2.0
        };
        done.replaced += 1;
    }
    done
}

/// The mean of the nearest good pixels of pixel `i`'s colour (`step`
/// apart) to its left and to its right along its row, or the one there is;
/// None when its row has none.
fn along_row(data: &[f32], width: usize, defective: &[bool], i: usize, step: usize) -> Option<f32> {
    let (row, x) = (i - i % width, i % width);
    let good = |j: usize| !defective[j] && data[j].is_finite();
    let step = step.max(1);
    let left = (step..=x)
        .step_by(step)
        .map(|d| row + x - d)
        .find(|&j| good(j));
    let right = (step..width - x)
        .step_by(step)
        .map(|d| row + x + d)
        .find(|&j| good(j));
    match (left, right) {
        (Some(a), Some(b)) => Some((data[a] + data[b]) / 2.0),
        (Some(a), None) | (None, Some(a)) => Some(data[a]),
        (None, None) => None,
    }
}

/// A light reduced: (light - bias - dark(t)) / flat, then cosmetic
/// correction; the pixels in DN above black, and the light's report
/// (its output path left for the caller).
pub fn reduce_frame(masters: &Masters, light: &RawFrame) -> (Vec<f32>, Option<DarkUsed>, Cosmetic) {
    let t = light.exposure_s.unwrap_or(0.0);
    let used = masters.dark_for(t).map(|(d, scale)| DarkUsed {
        master: d.name(),
        scale,
        temperature_scale: masters.temperature_scale(light.temperature_c),
    });
    let temperature = used.as_ref().and_then(|d| d.temperature_scale);
    let dark = masters.dark_signal(t, temperature.unwrap_or(1.0));
    let mut defective = masters.defective.clone();
    let mut out: Vec<f32> = (0..light.mosaic.len())
        .map(|i| {
            let f = masters.flat_norm[i];
            if f.is_nan() || f <= 0.0 {
                // No light reaches it in the flat: cosmetic correction
                // gives it its neighbours' value.
                defective[i] = true;
                return f32::NAN;
            }
            (f32::from(light.mosaic[i]) - masters.bias.samples[i] - dark[i]) / f
        })
        .collect();
    let step = if masters.mono { 1 } else { 2 };
    let cosmetic = replace_defects(&mut out, light.width, &defective, step);
    (out, used, cosmetic)
}

/// The output file of `light` in `dir`: its file name with only the final
/// extension changed, `.fits` for a FITS light, `.dng` for a camera RAW
/// (`M51.00000003.FIT` -> `M51.00000003.fits`, `M51.00000004.DARK.FIT` ->
/// `M51.00000004.DARK.fits`), so lights of one folder with different names
/// keep different names unless they differ only in that extension.
fn output_of(dir: &Path, light: &Path, fits: bool) -> PathBuf {
    let mut name = light.file_stem().unwrap_or(light.as_os_str()).to_owned();
    name.push(if fits { ".fits" } else { ".dng" });
    dir.join(name)
}

/// `lights` with each folder replaced by its files, sorted by name
/// (hidden files left out; [`pgrf_raw::files::list_files`]).
fn list_lights(lights: &[PathBuf]) -> Result<Vec<PathBuf>, ReduceError> {
    let mut out = Vec::with_capacity(lights.len());
    for l in lights {
        match l.is_dir() {
            true => out.extend(pgrf_raw::files::list_files(l)?),
            false => out.push(l.clone()),
        }
    }
    Ok(out)
}

fn is_fits_file(p: &Path) -> bool {
    pgrf_raw::FrameFormat::of_path(p).ok() == Some(pgrf_raw::FrameFormat::Fits)
}

/// Reduce `config.lights` with the masters and calibration and write each
/// result into `config.output`. The calibration, the masters and every
/// light are checked, and every output path, before anything is written;
/// the lights are then read again one at a time (memory holds one).
/// Reports lights done to `progress`.
pub fn reduce_to_files(
    config: &ReduceConfig,
    progress: &dyn Progress,
) -> Result<ReduceOutcome, ReduceError> {
    crate::calibrate::check_temperature_tolerance(config.temperature_tolerance)?;
    let config = &ReduceConfig {
        lights: list_lights(&config.lights)?,
        ..config.clone()
    };
    let calib = Calibration::load(&config.calib)?;
    let masters = load_masters(&config.masters, &calib, &config.calib)?;
    let outputs: Vec<PathBuf> = config
        .lights
        .iter()
        .map(|l| output_of(&config.output, l, is_fits_file(l)))
        .collect();
    check_light_outputs(config, &outputs)?;
    progress.start(
        2 * config.lights.len() as u64,
        "lights (checked, then reduced)",
    );
    for light in &config.lights {
        let frame = decode_file(light, &LevelOverrides::default())?;
        check_light(config, &calib, &masters, light, &frame)?;
        progress.advance(1);
    }
    std::fs::create_dir_all(&config.output).map_err(|e| ReduceError::Write {
        path: config.output.clone(),
        reason: e.to_string(),
    })?;
    let calib_name = config
        .calib
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut done = Vec::with_capacity(config.lights.len());
    for (light, output) in config.lights.iter().zip(outputs) {
        done.push(reduce_light(&masters, light, output, &calib_name)?);
        progress.advance(1);
    }
    progress.finish();
    Ok(ReduceOutcome {
        lights: done,
        bias: masters.bias.name(),
        flat: masters.flat.name(),
        law: law_name(masters.law),
    })
}

/// Reduce `light` with `masters` into `output` (FITS for a FITS light,
/// else a DNG on the light's levels); `calib_name` names the calibration
/// in the FITS header.
fn reduce_light(
    masters: &Masters,
    light: &Path,
    output: PathBuf,
    calib_name: &str,
) -> Result<ReducedLight, ReduceError> {
    let mut frame = decode_file(light, &LevelOverrides::default())?;
    let (pixels, dark, cosmetic) = reduce_frame(masters, &frame);
    let written = if frame.fits.is_some() {
        let (cards, history) = header_of(masters, &frame, dark.as_ref(), cosmetic, calib_name);
        pgrf_raw::encode_fits_light(&frame, &pixels, &cards, &history)
            .and_then(|bytes| Ok(pgrf_core::write_atomic(&output, &bytes)?))
    } else {
        // A DNG holds integers above its black level: the result is put
        // back on the light's black, rounded and clipped to the light's
        // range (a negative noise excursion clips at 0).
        let w = frame.width;
        frame.mosaic = (pixels.iter().enumerate())
            .map(|(i, &v)| {
                (v + frame.black_at(i / w, i % w))
                    .round()
                    .clamp(0.0, frame.white as f32) as u16
            })
            .collect();
        pgrf_raw::write_dng(&frame, &output, &Default::default())
    };
    written.map_err(|e| ReduceError::Write {
        path: output.clone(),
        reason: e.to_string(),
    })?;
    Ok(ReducedLight {
        input: light.to_path_buf(),
        output,
        exposure_s: frame.exposure_s,
        dark,
        cosmetic,
    })
}

/// No two lights may share an output (lights of one stem in two folders),
/// and, once the output folder exists, no output may be an input (the
/// command-line check has made sure it holds none when it does not).
fn check_light_outputs(config: &ReduceConfig, outputs: &[PathBuf]) -> Result<(), ReduceError> {
    for (i, o) in outputs.iter().enumerate() {
        if let Some(j) = outputs[..i].iter().position(|p| p == o) {
            return Err(ReduceError::SameOutput {
                output: o.clone(),
                first: config.lights[j].clone(),
                second: config.lights[i].clone(),
            });
        }
    }
    if config.output.is_dir() {
        let flagged: Vec<(&str, &Path)> = outputs.iter().map(|p| ("-o", p.as_path())).collect();
        let inputs: Vec<&Path> = config.lights.iter().map(|p| p.as_path()).collect();
        check_outputs(&flagged, &inputs).map_err(CalibError::from)?;
    }
    Ok(())
}

/// The header cards naming the masters and the HISTORY of the steps.
fn header_of(
    masters: &Masters,
    light: &RawFrame,
    dark: Option<&DarkUsed>,
    cosmetic: Cosmetic,
    calib_name: &str,
) -> (Vec<FitsCard>, Vec<String>) {
    let ascii = pgrf_raw::fits::card_text;
    let mut cards = vec![FitsCard::new(
        "MBIAS",
        FitsValue::Str(ascii(&masters.bias.name())),
        "master bias subtracted",
    )];
    let mut history = vec![format!(
        "pgrf reduce {}: light minus master bias {}",
        env!("CARGO_PKG_VERSION"),
        ascii(&masters.bias.name())
    )];
    if let Some(d) = dark {
        let (dark_cards, step) = dark_step(masters, light, &d.master, d.scale);
        cards.extend(dark_cards);
        history.push(step);
        if let Some((card, step)) = temperature_step(masters, light, d) {
            cards.push(card);
            history.push(step);
        }
    }
    cards.push(FitsCard::new(
        "MFLAT",
        FitsValue::Str(ascii(&masters.flat.name())),
        "master flat divided by",
    ));
    let means: Vec<String> = masters
        .flat_means
        .iter()
        .map(|m| format!("{m:.2}"))
        .collect();
    history.push(format!(
        "divided by master flat {} minus bias and dark, over its mean per plane ({} DN)",
        ascii(&masters.flat.name()),
        means.join(", ")
    ));
    cards.push(FitsCard::new(
        "CALIB",
        FitsValue::Str(ascii(calib_name)),
        "calibration: dark law, defects",
    ));
    cards.push(FitsCard::new(
        "NDEFECT",
        FitsValue::Int(cosmetic.replaced as i64),
        "pixels replaced (cosmetic)",
    ));
    history.extend(cosmetic_history(cosmetic, &ascii(calib_name)));
    history.push("pixels in DN above black / 65535".into());
    (cards, history)
}

/// The DARKTSCL card and HISTORY line of `dark` scaled to `light`'s
/// temperature, when it was ([`Masters::temperature_scale`]).
fn temperature_step(
    masters: &Masters,
    light: &RawFrame,
    dark: &DarkUsed,
) -> Option<(FitsCard, String)> {
    let f = dark.temperature_scale?;
    let (calib_c, doubling) = masters.dark_temperature?;
    let card = FitsCard::new(
        "DARKTSCL",
        FitsValue::Float(f),
        "dark scale to the light's temperature",
    );
    let step = format!(
        "dark scaled from {calib_c:.1} C to the light's {:.1} C: x{f:.6} (doubling every {doubling:.2} C)",
        light.temperature_c.unwrap_or(calib_c)
    );
    Some((card, step))
}

/// The HISTORY lines of cosmetic correction with the defects of
/// calibration `calib_name`.
fn cosmetic_history(cosmetic: Cosmetic, calib_name: &str) -> Vec<String> {
    let mut lines = vec![format!(
        "cosmetic: {} defective pixels of {calib_name} replaced by the median of same-colour neighbours",
        cosmetic.replaced
    )];
    if cosmetic.along_row > 0 {
        lines.push(format!(
            "{} of them, with no good neighbour, by the nearest good pixels along the row",
            cosmetic.along_row
        ));
    }
    if cosmetic.kept > 0 {
        lines.push(format!(
            "{} defective pixels kept: no good pixel of their colour in their row",
            cosmetic.kept
        ));
    }
    lines
}

/// The cards and the HISTORY line of the dark subtraction: master `name`
/// scaled by `scale` to the light's exposure.
fn dark_step(
    masters: &Masters,
    light: &RawFrame,
    name: &str,
    scale: f64,
) -> ([FitsCard; 3], String) {
    let ascii = pgrf_raw::fits::card_text;
    let cards = [
        FitsCard::new(
            "MDARK",
            FitsValue::Str(ascii(name)),
            "master dark subtracted",
        ),
        FitsCard::new(
            "DARKSCL",
            FitsValue::Float(scale),
            "dark signal scale g(t)/g(t_d)",
        ),
        FitsCard::new(
            "DARKLAW",
            FitsValue::Str(law_name(masters.law).into()),
            "dark law g: linear t, sqrt sqrt(t)",
        ),
    ];
    let offset = if masters.offset.is_some() {
        " (offset c kept unscaled)"
    } else {
        ""
    };
    let step = format!(
        "minus master dark {} minus bias, scaled to {} s by the {} law: x{scale:.6}{offset}",
        ascii(name),
        light.exposure_s.unwrap_or(0.0) as f32,
        law_name(masters.law)
    );
    (cards, step)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A temperature tolerance that is no number of °C, 0 or more, is
    /// refused by the library before any file is read (the paths here do
    /// not exist), for reduce and calibrate alike (the Python package calls
    /// them without the command's flag checks).
    #[test]
    fn a_bad_temperature_tolerance_is_refused_before_any_file_is_read() {
        let nowhere = PathBuf::from("/nonexistent/pgrf");
        for t in [-1.0, f32::NAN, f32::INFINITY] {
            let config = ReduceConfig {
                lights: vec![nowhere.join("light.fits")],
                masters: nowhere.join("masters"),
                calib: nowhere.join("calib.safetensors"),
                output: nowhere.join("out"),
                temperature_tolerance: Some(t),
            };
            let e = reduce_to_files(&config, &pgrf_core::NoProgress)
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("--temperature-tolerance must be a non-negative number of °C"),
                "{e}"
            );
            let input = crate::CalibrateInput {
                bias: vec![nowhere.join("b1.fits"), nowhere.join("b2.fits")],
                flat: vec![nowhere.join("f1.fits"), nowhere.join("f2.fits")],
                temperature_tolerance: Some(t),
                ..Default::default()
            };
            let e = crate::calibrate(&input, &pgrf_core::NoProgress)
                .err()
                .expect("refused")
                .to_string();
            assert!(
                e.contains("--temperature-tolerance must be a non-negative number of °C"),
                "{e}"
            );
        }
    }

    /// A defective pixel takes the median of its good same-colour
    /// neighbours: at step 2 on a Bayer mosaic (its own plane), at step 1
    /// on a monochrome sensor; defective neighbours are left out.
    #[test]
    fn defects_take_the_median_of_good_same_colour_neighbours() {
        let (w, h) = (6, 6);
        let data: Vec<f32> = (0..w * h).map(|i| i as f32).collect();
        let mut bad = vec![false; w * h];
        bad[2 * w + 2] = true;
        bad[2 * w + 4] = true;
        // Step 2 around (2, 2): (0,0) 0, (0,2) 2, (0,4) 4, (2,0) 12,
        // (4,0) 24, (4,2) 26, (4,4) 28; (2,4) is defective. Median of
        // seven: 12.
        let mut bayer = data.clone();
        assert_eq!(replace_defects(&mut bayer, w, &bad, 2).replaced, 2);
        assert_eq!(bayer[2 * w + 2], 12.0);
        // Step 1 around (2, 2): 7, 8, 9, 13, 15, 19, 20, 21: median 14.
        let mut mono = data.clone();
        replace_defects(&mut mono, w, &bad, 1);
        assert_eq!(mono[2 * w + 2], 14.0);
        // Untouched elsewhere.
        assert_eq!(mono[0], 0.0);
    }

    /// A monochrome sensor's columns 0, 1, W - 2 and W - 1 defective (no
    /// good neighbour for columns 0 and W - 1 in their 3 x 3) are filled
    /// from the nearest good pixels along their rows (columns 2 and W - 3),
    /// and counted; a row with no good pixel keeps its values, counted too.
    #[test]
    fn edge_columns_without_good_neighbours_are_filled_along_the_row() {
        let (w, h) = (8, 4);
        let data: Vec<f32> = (0..w * h)
            .map(|i| (i % w) as f32 * 10.0 + (i / w) as f32)
            .collect();
        let mut bad: Vec<bool> = (0..w * h).map(|i| matches!(i % w, 0 | 1 | 6 | 7)).collect();
        let mut mono = data.clone();
        let done = replace_defects(&mut mono, w, &bad, 1);
        // Columns 1 and 6 have good neighbours in their ring (2 and 5):
        // medians; columns 0 and 7 take columns 2 and 5 of their row.
        assert_eq!(
            done,
            Cosmetic {
                replaced: 16,
                along_row: 8,
                kept: 0
            }
        );
        for y in 0..h {
            assert_eq!(mono[y * w], data[y * w + 2], "row {y}");
            assert_eq!(mono[y * w + 7], data[y * w + 5], "row {y}");
        }
        // With row 1 all defective, its pixels at columns 0 and 7 have no
        // good pixel in their ring or their row: kept (a NaN becomes 0);
        // the others take their ring's rows 0 and 2.
        bad[w..2 * w].iter_mut().for_each(|b| *b = true);
        let mut mono = data.clone();
        mono[w] = f32::NAN;
        let done = replace_defects(&mut mono, w, &bad, 1);
        assert_eq!(done.kept, 2, "{done:?}");
        assert_eq!((mono[w], mono[w + 7]), (0.0, data[w + 7]));
    }

    fn master(t: f64) -> MasterFrame {
        MasterFrame {
            path: PathBuf::from(format!("master_dark_{t}s.fits")),
            exposure_s: t,
            samples: vec![100.0; 4],
        }
    }

    /// The dark nearest in ratio, a tie to the longer, scaled by the law:
    /// 20 s from darks of 10 and 40 s is a tie (x2 either way), so 40 s,
    /// sqrt(20 / 40) = 0.7071; 12 s takes 10 s, linear 1.2.
    #[test]
    fn the_nearest_dark_in_ratio_is_scaled_by_the_law() {
        let mut m = Masters {
            bias: MasterFrame {
                path: "master_bias.fits".into(),
                exposure_s: 0.0,
                samples: vec![90.0; 4],
            },
            darks: vec![master(10.0), master(40.0)],
            flat: master(1.0),
            flat_norm: vec![1.0; 4],
            flat_means: vec![1.0],
            law: Some(DarkLaw::Sqrt),
            offset: None,
            defective: vec![false; 4],
            size: (2, 2),
            mono: true,
            cfa: pgrf_raw::Cfa::Rggb,
            binning: None,
            dark_temperature: None,
        };
        let (d, s) = m.dark_for(20.0).unwrap();
        assert_eq!(d.exposure_s, 40.0);
        assert!((s - 0.5f64.sqrt()).abs() < 1e-12, "{s}");
        m.law = Some(DarkLaw::Linear);
        let (d, s) = m.dark_for(12.0).unwrap();
        assert_eq!(d.exposure_s, 10.0);
        assert!((s - 1.2).abs() < 1e-12, "{s}");
        // (100 - 90) * 1.2 per pixel; with an offset c = 4: 4 + 6 * 1.2.
        assert!(m
            .dark_signal(12.0, 1.0)
            .iter()
            .all(|&v| (v - 12.0).abs() < 1e-5));
        m.offset = Some(vec![4.0; 4]);
        assert!(m
            .dark_signal(12.0, 1.0)
            .iter()
            .all(|&v| (v - 11.2).abs() < 1e-5));
    }
}
