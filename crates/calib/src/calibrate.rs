//! One calibration run: read the stacks, estimate, assemble the file.

use crate::calibration::{CalibMaps, CalibMeta, Calibration};
use crate::error::{CalibError, Result};
use crate::estimate::{
    defect, defects, estimate_bias, estimate_dark, estimate_gain, BiasEstimate, DarkEstimate,
    GainEstimate,
};
use crate::masters::{masters_of, Master};
use crate::stack::{read_stack, FrameKey, ReadOptions, Stack};
use pgrf_core::Progress;
use pgrf_noise::DarkLaw;
use std::path::PathBuf;

/// The frames of one calibration run, all of one camera at one ISO.
#[derive(Clone, Debug, Default)]
pub struct CalibrateInput {
    /// Bias frames: shortest exposure, lens capped (one exposure time).
    pub bias: Vec<PathBuf>,
    /// Dark frames: lens capped, two or more exposure times; empty to skip
    /// dark current.
    pub dark: Vec<PathBuf>,
    /// Flat fields: evenly lit, unsaturated, one or more brightness levels
    /// set by exposure time (two or more for a photon-transfer fit).
    pub flat: Vec<PathBuf>,
    /// Expected ISO; frames of another ISO are refused. Used when files carry none.
    pub iso: Option<u32>,
    /// Pixels whose temporal samples are kept for the normality check.
    pub tap_pixels: usize,
    /// Keep each stack's mean as a master frame ([`CalibrationRun::masters`]).
    pub masters: bool,
    /// How far (degrees C) a frame's recorded temperature may lie from the
    /// median of all frames' before the run is refused; `None` for
    /// [`TEMPERATURE_TOLERANCE_C`].
    pub temperature_tolerance: Option<f32>,
    /// Dark frames taken at other sensor temperatures than the rest (two or
    /// more exposures not needed): with the darks, they measure the
    /// temperature rise that doubles the dark current
    /// ([`crate::temperature`]).
    pub temperature_darks: Vec<PathBuf>,
    /// Drop the frames that stand out from their stack
    /// ([`crate::stack::Stack::odd_frames`]) and read the stack again
    /// without them; without it they are kept and named in warnings.
    pub reject: bool,
}

/// What [`calibrate()`] returns: the calibration to save, and the estimates it
/// was assembled from (for reports and checks).
pub struct CalibrationRun {
    /// The calibration file's content.
    pub calibration: Calibration,
    /// The bias-frame estimates (fixed pattern, read noise, row noise, DSNU).
    pub bias: BiasEstimate,
    /// The flat-field estimates (K, photon-transfer curve, response).
    pub gain: GainEstimate,
    /// The dark-frame estimates, None without dark frames.
    pub dark: Option<DarkEstimate>,
    /// The master frames (bias, dark per exposure, flat per level), with
    /// [`CalibrateInput::masters`].
    pub masters: Vec<Master>,
    /// What every frame shared (size, CFA, levels, ISO, camera).
    pub key: FrameKey,
}

/// The dark law's name as the record writes it.
pub fn law_name(law: Option<DarkLaw>) -> &'static str {
    match law {
        Some(DarkLaw::Sqrt) => "sqrt",
        Some(DarkLaw::Linear) => "linear",
        None => "none",
    }
}

/// The dark law as people read it: "linear", "sqrt + c", ...
pub fn law_label(law: Option<DarkLaw>, offset: bool) -> String {
    let plus = if offset && law.is_some() { " + c" } else { "" };
    format!("{}{plus}", law_name(law))
}

impl CalibrationRun {
    /// Temporal noise variance without light, DN^2: the bias frames' mean
    /// per-pixel variance (read noise, row noise, offset drift).
    pub fn dark_variance(&self) -> f64 {
        self.bias.var.mean().unwrap_or(0.0)
    }

    /// The sensor's noise in the DNG NoiseProfile form (tag 51041): variance
    /// S x + O at signal x normalised to [0, 1] (black 0, white 1), with
    /// S = K / (white - black) and O = the dark temporal variance
    /// ([`CalibrationRun::dark_variance`]: read, row and offset drift) over
    /// (white - black)^2. What DNG readers and `--profile dng:` take.
    pub fn noise_profile(&self) -> [f64; 2] {
        let m = &self.calibration.meta;
        let black = m.black.iter().map(|&b| b as f64).sum::<f64>() / 4.0;
        let range = m.white as f64 - black;
        [m.k / range, self.dark_variance() / (range * range)]
    }

    /// The run's figures as (quantity, value, unit) rows in EMVA 1288's
    /// vocabulary (system gain, temporal dark noise, DSNU, PRNU, dark
    /// current, ...), formatted for the report's summary table.
    pub fn summary(&self) -> Vec<(String, String, String)> {
        let mut summary = self.gain_rows();
        summary.extend(self.noise_rows());
        summary.extend(self.response_rows());
        summary.extend(self.dark_rows());
        summary.extend(self.record_rows());
        summary
    }

    /// The system gain, by each of the ways it was measured.
    fn gain_rows(&self) -> Vec<Row> {
        let m = &self.calibration.meta;
        vec![
            row(
                "System gain K",
                match m.k_sigma {
                    Some(e) => format!("{:.4} ± {e:.4} ({})", m.k, m.k_method),
                    None => format!("{:.4} ({})", m.k, m.k_method),
                },
                "DN/e-",
            ),
            row(
                "Inverse system gain 1/K",
                format!("{:.4}", 1.0 / m.k),
                "e-/DN",
            ),
            row(
                "System gain, eq. 3.15 at the brightest level",
                format!("{:.4}", self.gain.k_var_mean),
                "DN/e-",
            ),
            row(
                "System gain from each pixel's variance over the stack (light drift not removed)",
                format!(
                    "{:.4} (light drift {:.2} % over the brightest level)",
                    self.gain.k_without_pairs,
                    100.0 * self.gain.levels.iter().map(|l| l.drift).fold(0.0, f64::max)
                ),
                "DN/e-",
            ),
        ]
    }

    /// Temporal and spatial noise, in DN with electrons beside them.
    fn noise_rows(&self) -> Vec<Row> {
        let m = &self.calibration.meta;
        // A DN figure with its electrons beside it, "-" when not measured.
        let dn_e = |v: Option<f64>| {
            v.map(|d| format!("{d:.3} ({:.3} e-)", d / m.k))
                .unwrap_or_else(|| "-".into())
        };
        vec![
            row(
                "Temporal dark noise sigma_y.dark (EMVA 1288: pair differences of the bias frames; row noise and quantisation included)",
                dn_e(m.dark_noise_sigma),
                "DN",
            ),
            row(
                &format!(
                    "Read noise (median over pixels of the per-pixel sigma, row noise removed; corrected for the sampling error of {} frames)",
                    m.bias_frames
                ),
                dn_e(Some(m.read_sigma_median)),
                "DN",
            ),
            row("Row noise sigma", format!("{:.3}", m.row_sigma), "DN"),
            row(
                "Whole-frame offset drift sigma (frame to frame, apart from row noise)",
                m.frame_offset_sigma
                    .map(|s| format!("{s:.3}"))
                    .unwrap_or_else(|| "-".into()),
                "DN",
            ),
            row(
                "DSNU (spatial sd of the dark offset)",
                dn_e(Some(m.dsnu)),
                "DN",
            ),
            row(
                "DSNU, EMVA 1288 (5x5 high-pass, outliers such as hot pixels excluded)",
                dn_e(m.dsnu_highpass),
                "DN",
            ),
            row(
                "PRNU (spatial sd of the response / mean)",
                m.prnu
                    .map(|p| format!("{:.3}", 100.0 * p))
                    .unwrap_or_else(|| "-".into()),
                "%",
            ),
            row(
                "PRNU, EMVA 1288 (5x5 high-pass: the flat's shading removed; outliers excluded)",
                m.prnu_highpass
                    .map(|p| format!("{:.3}", 100.0 * p))
                    .unwrap_or_else(|| "-".into()),
                "%",
            ),
        ]
    }

    /// Saturation, linearity, SNR by level and the DNG noise profile.
    fn response_rows(&self) -> Vec<Row> {
        let m = &self.calibration.meta;
        let mut summary = Vec::new();
        summary.push(row(
            "Saturation capacity (EMVA 1288: the level of largest variance)",
            match m.saturation_capacity_e {
                Some(e) => format!("{e:.0} e- ({:.0} DN)", e * m.k),
                None => "not measured (no flat level reached saturation)".into(),
            },
            "",
        ));
        summary.push(row(
            "Linearity error (EMVA 1288, levels at 5-95 % of saturation)",
            m.linearity_error
                .map(|l| format!("{:.2}", 100.0 * l))
                .unwrap_or_else(|| "not measured (fewer than three levels there)".into()),
            "%",
        ));
        let bias_var = self.dark_variance();
        let snr: Vec<String> = self
            .gain
            .levels
            .iter()
            .map(|l| {
                format!(
                    "{:.1} at {:.0} DN",
                    l.mean_dn / (l.var_dn2 + bias_var).max(f64::MIN_POSITIVE).sqrt(),
                    l.mean_dn
                )
            })
            .collect();
        summary.push(row("SNR by flat level", snr.join(", "), ""));
        let [s, o] = self.noise_profile();
        summary.push(row(
            "DNG NoiseProfile (variance S x + O, x in [0, 1])",
            format!("S {s:.4e}, O {o:.4e}"),
            "",
        ));
        summary
    }

    /// Dark current and its fit, or why it was not measured.
    fn dark_rows(&self) -> Vec<Row> {
        let m = &self.calibration.meta;
        let mut summary = Vec::new();
        match (m.dark_rate_mean, m.dark_r2_sqrt, m.dark_r2_linear) {
            (Some(rate), Some(rs), Some(rl)) => {
                let unit = m.dark_rate_unit().unwrap_or_default();
                let plus = if m.dark_offset { " + c" } else { "" };
                let at = m
                    .temperature_c
                    .map(|t| format!(" at {t:.1} °C"))
                    .unwrap_or_default();
                summary.push(row(
                    &format!(
                        "Dark current (mean, {} law){at}",
                        law_label(m.dark_law, m.dark_offset)
                    ),
                    format!("{rate:.4}"),
                    unit,
                ));
                if let Some(c) = m.dark_offset_mean {
                    summary.push(row(
                        "Dark signal offset c (mean)",
                        format!("{c:.3} ({:.2} e-)", c / m.k),
                        "DN",
                    ));
                }
                summary.push(row(
                    &format!("Dark signal fit R^2, a*sqrt(t){plus} / a*t{plus}"),
                    format!("{rs:.5} / {rl:.5}"),
                    "",
                ));
            }
            _ => summary.push(row(
                "Dark current",
                "not measured (no dark frames)".into(),
                "",
            )),
        }
        summary
    }

    /// Temperature, warnings, rejected frames, defects, normality and frame counts.
    fn record_rows(&self) -> Vec<Row> {
        let m = &self.calibration.meta;
        let mut summary = Vec::new();
        summary.push(row(
            "Capture temperature (median of the frames)",
            m.temperature_c
                .map(|t| format!("{t:.1} °C"))
                .unwrap_or_else(|| "not recorded in the files".into()),
            "",
        ));
        for w in &m.warnings {
            summary.push(row("Warning", w.clone(), ""));
        }
        for r in &m.rejected_frames {
            summary.push(row("Rejected", r.clone(), ""));
        }
        summary.push(row(
            "Hot / dead / cold pixels; defective columns",
            format!(
                "{} / {} / {} pixels; {} columns",
                m.hot_pixels, m.dead_pixels, m.cold_pixels, m.defect_columns
            ),
            "",
        ));
        if let (Some(p), Some(g)) = (m.ppcc_pixel_median, m.ppcc_pooled) {
            summary.push(row(
                "Read-noise normality: PPCC per pixel (median) / pooled",
                format!("{p:.4} / {g:.4}"),
                "",
            ));
        }
        summary.push(row(
            "Frames: bias / dark / flat",
            format!(
                "{} / {} / {}",
                m.bias_frames,
                m.dark_frames
                    .iter()
                    .map(|n| n.to_string())
                    .collect::<Vec<_>>()
                    .join("+"),
                m.flat_frames
                    .iter()
                    .map(|n| n.to_string())
                    .collect::<Vec<_>>()
                    .join("+")
            ),
            "",
        ));
        summary
    }
}

/// One summary row: quantity, value, unit.
type Row = (String, String, String);

fn row(q: &str, v: String, u: &str) -> Row {
    (q.to_string(), v, u.to_string())
}

/// How far apart (degrees C) the frames of one calibration may have been
/// taken unless told otherwise: dark current doubles every 5-7 degrees, so
/// 2 degrees already moves it by a quarter.
pub const TEMPERATURE_TOLERANCE_C: f32 = 2.0;

/// Refuse a temperature tolerance (`--temperature-tolerance`, of
/// `pgrf calibrate` and `pgrf reduce`) that is not a number of °C, 0 or more.
pub fn check_temperature_tolerance(t: Option<f32>) -> Result<()> {
    match t {
        Some(t) if !(t.is_finite() && t >= 0.0) => Err(CalibError::BadOption {
            flag: "--temperature-tolerance",
            message: format!(
                "--temperature-tolerance must be a non-negative number of °C, got {t}"
            ),
        }),
        _ => Ok(()),
    }
}

/// The median temperature of the frames that record one, after checking
/// that none lies further than `tolerance` from it (the file furthest out
/// is named).
fn check_temperatures(sets: &[&[(PathBuf, f32)]], tolerance: f32) -> Result<Option<f32>> {
    let all: Vec<&(PathBuf, f32)> = sets.iter().flat_map(|s| s.iter()).collect();
    if all.is_empty() {
        return Ok(None);
    }
    let mut v: Vec<f64> = all.iter().map(|(_, t)| *t as f64).collect();
    let med = pgrf_core::stats::median(&mut v) as f32;
    let worst = all
        .iter()
        .max_by(|a, b| (a.1 - med).abs().total_cmp(&(b.1 - med).abs()))
        .expect("not empty");
    if (worst.1 - med).abs() > tolerance {
        return Err(CalibError::TemperatureSpread {
            file: worst.0.clone(),
            temperature_c: worst.1,
            median_c: med,
            tolerance,
        });
    }
    Ok(Some(med))
}

/// Read a stack, then deal with the frames that stand out from it
/// ([`Stack::odd_frames`]): named in `notes`, or with `reject` dropped (the
/// stack read again without them) and listed in `rejected`.
fn read_checked(
    files: &[PathBuf],
    opt: &ReadOptions,
    reject: bool,
    notes: &mut Vec<String>,
    rejected: &mut Vec<String>,
) -> Result<Stack> {
    let stack = read_stack(files, opt)?;
    let odd = stack.odd_frames(opt.kind);
    if odd.is_empty() {
        return Ok(stack);
    }
    if !reject {
        notes.extend(
            odd.iter()
                .map(|o| format!("{}; kept (--reject drops such frames)", o.why)),
        );
        return Ok(stack);
    }
    let keep: Vec<PathBuf> = files
        .iter()
        .filter(|f| !odd.iter().any(|o| &o.file == *f))
        .cloned()
        .collect();
    rejected.extend(odd.into_iter().map(|o| o.why));
    read_stack(&keep, opt)
}

/// The per-pixel gain map as the file keeps it: 0 at the pixels the defect
/// map calls dead, whose eq. 3.15 is a ratio of noise to a signal they do
/// not have (or NaN where it is none at all).
fn responding_gain(
    k_map: &ndarray::Array3<f32>,
    defects: &ndarray::Array3<f32>,
) -> ndarray::Array3<f32> {
    let mut out = k_map.clone();
    ndarray::Zip::from(&mut out).and(defects).for_each(|k, &d| {
        if d == defect::DEAD || !k.is_finite() {
            *k = 0.0;
        }
    });
    out
}

/// Calibrate a sensor from its bias, flat and (optional) dark stacks: read
/// each stack with streaming statistics (frames must match the first bias
/// frame), estimate bias, gain and dark current, flag defects, and assemble
/// the per-pixel maps (packed `(4, H/2, W/2)`, R, G1, B, G2) and the record.
/// Reports frames read to `progress`.
pub fn calibrate(input: &CalibrateInput, progress: &dyn Progress) -> Result<CalibrationRun> {
    let tolerance = tolerance_of(input)?;
    let (mut notes, mut rejected) = (Vec::new(), Vec::new());
    let (bias_stack, key) = read_bias(input, progress, &mut notes, &mut rejected)?;
    let bias = estimate_bias(&bias_stack, key.black)?;
    let opts = |kind, per_exposure, pairs| {
        ReadOptions::after_bias(kind, &bias_stack.key, per_exposure, pairs, progress)
    };
    let flat_stack = read_checked(
        &input.flat,
        &opts("flat", 2, true),
        input.reject,
        &mut notes,
        &mut rejected,
    )?;
    check_temperatures(
        &[&bias_stack.temperatures, &flat_stack.temperatures],
        tolerance,
    )?;
    let gain = estimate_gain(&flat_stack, &bias)?;
    let mut masters = Vec::new();
    if input.masters {
        masters = [
            masters_of(&bias_stack, "bias"),
            masters_of(&flat_stack, "flat"),
        ]
        .concat();
    }
    let darks = read_darks(
        input,
        &opts,
        (&bias, &gain),
        (&mut notes, &mut rejected),
        &mut masters,
    )?;
    let dark = darks.estimate;
    let temperature_c = check_temperatures(
        &[
            &bias_stack.temperatures,
            &flat_stack.temperatures,
            &darks.temperatures,
        ],
        tolerance,
    )?;
    let (defect_map, defect_columns) =
        defects(&bias, Some(&gain), dark.as_ref(), key.cfa.offsets());
    let mut maps = maps_of(&bias, &gain, dark.as_ref(), defect_map);
    maps.noise_bank = crate::bank::bank_of(&bias_stack, &bias.mean);
    let mut meta = meta_of(&Measured {
        key: &key,
        bias: &bias,
        bias_exposure_s: bias_stack.groups[0].exposure_s,
        gain: &gain,
        dark: dark.as_ref(),
        dark_frames: darks.frames,
        temperature_c,
        notes,
        rejected,
        defects: &maps.defects,
        defect_columns,
    });
    meta.dark_doubling_c = crate::temperature::doubling_temperature(&darks.rates);
    meta.dark_rates_by_temperature = darks.rates;
    Ok(CalibrationRun {
        calibration: Calibration { meta, maps },
        bias,
        gain,
        dark,
        masters,
        key,
    })
}

/// What the dark stacks gave: the estimate, the frames per exposure, the
/// frames' temperatures and the rates at each temperature.
struct Darks {
    estimate: Option<DarkEstimate>,
    frames: Vec<usize>,
    temperatures: Vec<(PathBuf, f32)>,
    rates: Vec<(f32, f64)>,
}

/// Read and estimate the dark stack (none without darks; temperature darks
/// need darks), its masters added to `masters`, and the rates at the
/// temperature darks' temperatures.
fn read_darks<'o>(
    input: &CalibrateInput,
    opts: &dyn Fn(&'static str, usize, bool) -> ReadOptions<'o>,
    (bias, gain): (&BiasEstimate, &GainEstimate),
    (notes, rejected): (&mut Vec<String>, &mut Vec<String>),
    masters: &mut Vec<Master>,
) -> Result<Darks> {
    if input.dark.is_empty() {
        if !input.temperature_darks.is_empty() {
            return Err(CalibError::BadOption {
                flag: "--temperature-darks",
                message: "--temperature-darks measure the dark current's growth against the darks at the calibration's temperature: give --dark too".into(),
            });
        }
        return Ok(Darks {
            estimate: None,
            frames: Vec::new(),
            temperatures: Vec::new(),
            rates: Vec::new(),
        });
    }
    let stack = read_checked(
        &input.dark,
        &opts("dark", 1, false),
        input.reject,
        notes,
        rejected,
    )?;
    if input.masters {
        masters.extend(masters_of(&stack, "dark"));
    }
    let dark = estimate_dark(&stack, bias, gain.k)?;
    let rates = match input.temperature_darks.is_empty() {
        true => Vec::new(),
        false => rates_with_temperature(input, &stack, bias, dark.law, &opts("dark", 1, false))?,
    };
    Ok(Darks {
        estimate: Some(dark),
        frames: stack.groups.iter().map(|g| g.files.len()).collect(),
        temperatures: stack.temperatures,
        rates,
    })
}

/// The dark rate at the darks' median temperature and at each temperature
/// of `input.temperature_darks` ([`crate::temperature`]).
fn rates_with_temperature(
    input: &CalibrateInput,
    darks: &crate::stack::Stack,
    bias: &BiasEstimate,
    law: pgrf_noise::DarkLaw,
    opt: &ReadOptions,
) -> Result<Vec<(f32, f64)>> {
    let mut temps: Vec<f64> = darks.temperatures.iter().map(|(_, t)| *t as f64).collect();
    if temps.is_empty() {
        return Err(CalibError::BadOption {
            flag: "--temperature-darks",
            message: "the darks record no temperature to compare with".into(),
        });
    }
    let here = pgrf_core::stats::median(&mut temps) as f32;
    let mut rates: Vec<(f32, f64)> = crate::temperature::median_rate(darks, bias, law)
        .map(|r| (here, r))
        .into_iter()
        .collect();
    rates.extend(crate::temperature::rates_by_temperature(
        &input.temperature_darks,
        opt,
        bias,
        law,
    )?);
    Ok(rates)
}

/// The temperature tolerance asked for (checked), else the default.
fn tolerance_of(input: &CalibrateInput) -> Result<f32> {
    check_temperature_tolerance(input.temperature_tolerance)?;
    Ok(input
        .temperature_tolerance
        .unwrap_or(TEMPERATURE_TOLERANCE_C))
}

/// The bias stack, read with the checks every frame must pass, and its
/// frames' shared key (the ISO asked for where the files record none; a
/// recorded ISO other than the one asked for is refused).
fn read_bias(
    input: &CalibrateInput,
    progress: &dyn Progress,
    notes: &mut Vec<String>,
    rejected: &mut Vec<String>,
) -> Result<(Stack, FrameKey)> {
    let bias_stack = read_checked(
        &input.bias,
        &ReadOptions::bias(input.tap_pixels, true, progress).with_bank(),
        input.reject,
        notes,
        rejected,
    )?;
    let mut key = bias_stack.key.clone();
    if let (Some(want), Some(got)) = (input.iso, key.iso) {
        if want != got {
            return Err(CalibError::StackIso {
                file: input.bias[0].clone(),
                found: got,
                asked: want,
            });
        }
    }
    if key.iso.is_none() {
        key.iso = input.iso;
    }
    Ok((bias_stack, key))
}

/// The per-pixel maps of the calibration file.
fn maps_of(
    bias: &BiasEstimate,
    gain: &GainEstimate,
    dark: Option<&DarkEstimate>,
    defect_map: ndarray::Array3<f32>,
) -> CalibMaps {
    let zeros = || ndarray::Array3::zeros(bias.fixed_pattern.raw_dim());
    CalibMaps {
        fixed_pattern: bias.fixed_pattern.clone(),
        sigma_read: bias.sigma_read.clone(),
        dark_rate: dark.map_or_else(zeros, |d| d.rate.clone()),
        gain: Some(responding_gain(&gain.k_map, &defect_map)),
        defects: defect_map,
        response: Some(gain.response.clone()),
        r2_sqrt: dark.map(|d| d.r2_sqrt.clone()),
        r2_linear: dark.map(|d| d.r2_linear.clone()),
        dark_offset: dark.and_then(|d| d.offset_dn.clone()),
        noise_bank: Vec::new(),
    }
}

/// What the calibration measured, for its record ([`meta_of`]).
struct Measured<'a> {
    key: &'a FrameKey,
    bias: &'a BiasEstimate,
    bias_exposure_s: f64,
    gain: &'a GainEstimate,
    dark: Option<&'a DarkEstimate>,
    dark_frames: Vec<usize>,
    temperature_c: Option<f32>,
    notes: Vec<String>,
    rejected: Vec<String>,
    defects: &'a ndarray::Array3<f32>,
    defect_columns: usize,
}

/// The calibration file's record (camera, levels, frames, the figures of
/// EMVA 1288 and the dark law, defect counts, units).
fn meta_of(r: &Measured) -> CalibMeta {
    let Measured {
        key,
        bias,
        gain,
        dark,
        ..
    } = *r;
    let count = |code: f32| r.defects.iter().filter(|&&d| d == code).count();
    let mut pp = bias.ppcc_pixels.clone();
    pp.sort_by(|a, b| a.total_cmp(b));
    CalibMeta {
        kind: "pgrf-calibration".into(),
        schema: 1,
        pgrf_version: env!("CARGO_PKG_VERSION").into(),
        make: key.make.clone(),
        model: key.model.clone(),
        iso: key.iso,
        width: key.width,
        height: key.height,
        cfa: key.layout().into(),
        black: key.black,
        white: key.white,
        bias_frames: bias.frames,
        bias_exposure_s: r.bias_exposure_s,
        dark_exposures_s: dark.map(|d| d.exposures.clone()).unwrap_or_default(),
        dark_frames: r.dark_frames.clone(),
        flat_exposures_s: gain.levels.iter().map(|l| l.exposure_s).collect(),
        flat_frames: gain.levels.iter().map(|l| l.frames).collect(),
        k: gain.k,
        k_method: gain.method,
        row_sigma: bias.row_sigma,
        frame_offset_sigma: Some(bias.frame_offset_sigma),
        read_sigma_median: bias.read_sigma_median,
        dark_noise_sigma: Some(bias.dark_noise_sigma).filter(|v| v.is_finite()),
        dsnu: bias.dsnu,
        prnu: Some(gain.prnu),
        dsnu_highpass: Some(bias.dsnu_highpass).filter(|v| v.is_finite()),
        prnu_highpass: Some(gain.prnu_highpass).filter(|v| v.is_finite()),
        k_sigma: Some(gain.k_sigma).filter(|v| v.is_finite()),
        saturation_capacity_e: gain.saturation_dn.map(|d| d / gain.k),
        linearity_error: gain.linearity_error,
        dark_law: dark.map(|d| d.law),
        dark_r2_sqrt: dark.map(|d| d.r2_sqrt_global),
        dark_r2_linear: dark.map(|d| d.r2_linear_global),
        dark_rate_mean: dark.map(|d| d.rate_mean),
        dark_rate_unit: dark
            .as_ref()
            .map(|d| crate::calibration::dark_rate_unit(d.law).to_string()),
        dark_offset: dark.is_some_and(|d| d.offset),
        dark_offset_mean: dark
            .as_ref()
            .filter(|d| d.offset)
            .map(|d| d.offset_mean_dn),
        temperature_c: r.temperature_c,
        warnings: gain.warnings.iter().cloned().chain(r.notes.iter().cloned()).collect(),
        rejected_frames: r.rejected.clone(),
        ppcc_pixel_median: pp.get(pp.len() / 2).copied(),
        ppcc_pooled: bias.ppcc_pooled.is_finite().then_some(bias.ppcc_pooled),
        hot_pixels: count(defect::HOT),
        dead_pixels: count(defect::DEAD),
        cold_pixels: count(defect::COLD),
        defect_columns: r.defect_columns,
        dark_doubling_c: None,
        dark_rates_by_temperature: Vec::new(),
        row_order: Some(key.row_order),
        units: format!("{}; fixed_pattern (bias mean - black), sigma_read, response: DN; gain: DN per electron (eq. 3.15 per pixel; 0 at dead pixels); dark_rate: electrons per sqrt(s) (sqrt law) or per s (linear law), N_FP absorbed; defects: 0 good, 1 hot, 2 dead, 3 cold, 4 defective column (defect_columns counts sensor columns); r2_*: R^2 of the per-pixel dark fits (with the offset term when dark_offset); dark_offset: the dark law's offset c, DN; K: DN/e-; row_sigma, read_sigma_median (median of the true per-pixel sigma, corrected for the frames' sampling error), dark_noise_sigma (EMVA 1288 sigma_y.dark from bias-frame pair differences), dsnu: DN", if key.mono { "maps in the file one plane (1, H, W) of the sensor's pixels (in memory packed as its four sub-lattices)" } else { "maps packed (4, H/2, W/2) in R,G1,B,G2 order" }),
    }
}
