//! `pgrf calibrate`: bias, dark and flat stacks in, a per-pixel calibration
//! file and a readable report out.

use crate::progress::Bar;
use anyhow::{Context, Result};
use clap::Args;
use pgrf_calib::{
    calibrate_to_files, CalibrateConfig, CalibrateInput, CalibrateOutcome, CalibrationRun,
    DarktableOutcome, DarktableOutput, ReportOutput, RunHooks,
};
use pgrf_raw::files::list_files;
use pgrf_report::{write_report, PtcPoint, ReportData, REPORT_FILES};
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub struct CalibrateArgs {
    /// Folder of bias frames (shortest exposure, lens capped).
    #[arg(long)]
    pub bias: PathBuf,
    /// Folder of dark frames (lens capped, two or more exposure times read from EXIF; any number of frames at each, one is fine).
    #[arg(long)]
    pub dark: Option<PathBuf>,
    /// Folder of flat-field frames (uniform light; two or more levels, told apart by exposure time).
    #[arg(long)]
    pub flat: PathBuf,
    /// ISO the frames must have (used when the files carry none).
    #[arg(long)]
    pub iso: Option<u32>,
    /// Output calibration file (safetensors maps + JSON record).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Folder for the report (PNG plots and summary.md); created if missing.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// End with one JSON line of the global results.
    #[arg(long)]
    pub json: bool,
    /// Drop frames whose mean or noise stands out from their stack (robust z-score above 5) instead of only naming them.
    #[arg(long)]
    pub reject: bool,
    /// How far (°C) a frame's recorded temperature may lie from the frames' median [default: 2].
    #[arg(long)]
    pub temperature_tolerance: Option<f32>,
    /// Folder for master frames (created if missing): master_bias.dng, one master_dark_EXPOSUREs.dng per dark exposure (master_dark_10s.dng), one master_flat_EXPOSUREs.dng per flat level (each stack's mean, in the camera's mosaic and levels) and defects.png.
    #[arg(long)]
    pub masters: Option<PathBuf>,
    /// Add the calibrated camera's darktable noise-profile entry (at its ISO) to this darktable noiseprofiles.json, created if missing: a copy of darktable's own file, or one that earlier calibrations at other ISOs wrote; an entry of the same camera at the same ISO is replaced. Without it the entry is written alone beside -o as OUTPUT.noiseprofiles.json. darktable reads such a file with `darktable --noiseprofiles FILE`.
    #[arg(long)]
    pub darktable_into: Option<PathBuf>,
    /// The maker name the darktable entry is filed under [default: the frames' maker as pgrf reads it, rawspeed's clean name for native RAWs]. darktable uses the entry for images whose maker contains this string.
    #[arg(long)]
    pub darktable_maker: Option<String>,
    /// The model name the darktable entry is filed under [default: the frames' model as pgrf reads it]. darktable uses the entry only for images whose model, as darktable names it, is exactly this: set it where the names differ (an alias: the EOS Kiss X4 is the EOS 550D, the name darktable's own file uses).
    #[arg(long)]
    pub darktable_model: Option<String>,
}

pub fn run(a: &CalibrateArgs) -> Result<()> {
    let config = config(a)?;
    let c = &config.input;
    let total = c.bias.len() + c.flat.len() + c.dark.len();
    let bar = Bar::new("calibrating", total as u64, "frames", false);
    let outcome = calibrate_to_files(&config, &bar, &Cli)?;
    tell(a, &outcome);
    if a.json {
        println!("{}", json_line(&outcome.run, &a.output));
    }
    Ok(())
}

/// The run `a` asks for, its options checked before any work: the report
/// and masters folders, the temperature tolerance, the darktable names.
fn config(a: &CalibrateArgs) -> Result<CalibrateConfig> {
    let bias = list_files(&a.bias)?;
    let flat = list_files(&a.flat)?;
    let dark = match &a.dark {
        Some(d) => list_files(d)?,
        None => Vec::new(),
    };
    if let Some(dir) = &a.report {
        if dir.exists() && !dir.is_dir() {
            anyhow::bail!(
                "--report {} is a file; give a folder for the report",
                dir.display()
            );
        }
        crate::output::require_parent_dir(dir).context("--report")?;
    }
    if let Some(t) = a.temperature_tolerance {
        if !(t.is_finite() && t >= 0.0) {
            anyhow::bail!("--temperature-tolerance must be a non-negative number of °C, got {t}");
        }
    }
    if let Some(dir) = &a.masters {
        if dir.exists() && !dir.is_dir() {
            anyhow::bail!("--masters {} is a file; give a folder", dir.display());
        }
        crate::output::require_parent_dir(dir).context("--masters")?;
    }
    for (flag, name) in [
        ("--darktable-maker", &a.darktable_maker),
        ("--darktable-model", &a.darktable_model),
    ] {
        if name.as_deref().is_some_and(|n| n.trim().is_empty()) {
            anyhow::bail!("{flag} is empty: darktable finds an entry by maker and model");
        }
    }
    Ok(CalibrateConfig {
        input: CalibrateInput {
            bias,
            dark,
            flat,
            iso: a.iso,
            tap_pixels: 4096,
            reject: a.reject,
            masters: a.masters.is_some(),
            temperature_tolerance: a.temperature_tolerance,
        },
        output: a.output.clone(),
        masters: a.masters.clone(),
        report: a.report.clone().map(|dir| ReportOutput {
            dir,
            files: REPORT_FILES.to_vec(),
        }),
        darktable: DarktableOutput {
            into: a.darktable_into.clone(),
            maker: a.darktable_maker.clone(),
            model: a.darktable_model.clone(),
        },
    })
}

/// The CLI's part of the run: its rules on where a command writes, and the
/// report's plots (pgrf-report, which pgrf-calib does not depend on).
struct Cli;

impl RunHooks for Cli {
    type Error = anyhow::Error;

    fn check_outputs(&self, outputs: &[(&str, &Path)], inputs: &[&Path]) -> Result<()> {
        crate::output::check_outputs(outputs, inputs)
    }

    fn write_report(&self, dir: &Path, run: &CalibrationRun) -> Result<usize> {
        Ok(write_report(dir, &report_data(run))?.len())
    }
}

/// What the run wrote and found, on stderr.
fn tell(a: &CalibrateArgs, outcome: &CalibrateOutcome) {
    if let DarktableOutcome::Skipped { lack } = &outcome.darktable {
        eprintln!("pgrf: note: the frames {lack}: no darktable noise profile written");
    }
    if let (Some(n), Some(dir)) = (outcome.masters, &a.masters) {
        eprintln!(
            "wrote {n} master frames and defects.png in {}",
            dir.display()
        );
    }
    if let (Some(n), Some(dir)) = (outcome.report, &a.report) {
        eprintln!("wrote report: {n} files in {}", dir.display());
    }
    if let DarktableOutcome::Written {
        path,
        replaced,
        name,
    } = &outcome.darktable
    {
        let replacing = match replaced {
            0 => String::new(),
            n => format!(", replacing {n} entry of that camera at that ISO"),
        };
        eprintln!(
            "wrote {}: darktable noise-profile entry \"{name}\"{replacing} (darktable reads the file with: darktable --noiseprofiles {})",
            path.display(),
            path.display()
        );
    }
    let m = &outcome.run.calibration.meta;
    for w in &m.warnings {
        eprintln!("pgrf: warning: {w}");
    }
    for r in &m.rejected_frames {
        eprintln!("pgrf: note: dropped {r}");
    }
    eprintln!(
        "wrote {}: K {:.4} DN/e- ({}), read sigma median {:.3} DN, row sigma {:.3} DN, DSNU {:.3} DN, dark law {}, {} hot / {} dead pixels",
        a.output.display(),
        m.k,
        m.k_method,
        m.read_sigma_median,
        m.row_sigma,
        m.dsnu,
        pgrf_calib::calibrate::law_label(m.dark_law, m.dark_offset),
        m.hot_pixels,
        m.dead_pixels
    );
}

/// The run's global results as one JSON line.
fn json_line(run: &CalibrationRun, output: &Path) -> serde_json::Value {
    let m = &run.calibration.meta;
    serde_json::json!({
        "K": m.k,
        "K_method": m.k_method,
        "row_sigma": m.row_sigma,
        "read_sigma_median": m.read_sigma_median,
        "dsnu": m.dsnu,
        "prnu": m.prnu,
        "dark_law": pgrf_calib::calibrate::law_name(m.dark_law),
        "dark_r2_sqrt": m.dark_r2_sqrt,
        "dark_r2_linear": m.dark_r2_linear,
        "dark_rate_mean": m.dark_rate_mean,
        "dark_offset": m.dark_offset,
        "dark_offset_mean": m.dark_offset_mean,
        "K_without_pairs": run.gain.k_without_pairs,
        "noise_profile": run.noise_profile(),
        "cfa": m.layout(),
        "temperature_c": m.temperature_c,
        "warnings": m.warnings,
        "rejected_frames": m.rejected_frames,
        "hot_pixels": m.hot_pixels,
        "dead_pixels": m.dead_pixels,
        "output": output.display().to_string(),
    })
}

fn report_data(run: &CalibrationRun) -> ReportData<'_> {
    let m = &run.calibration.meta;
    let maps = &run.calibration.maps;
    ReportData {
        camera: format!("{} {}", m.make, m.model),
        iso: m.iso,
        ptc_points: run
            .gain
            .levels
            .iter()
            .map(|l| PtcPoint {
                mean_dn: l.mean_dn,
                var_dn2: l.var_dn2,
            })
            .collect(),
        ptc_fit: run.gain.ptc_fit,
        sigma_read: maps.sigma_read.view(),
        fixed_pattern: maps.fixed_pattern.view(),
        r2_sqrt: maps.r2_sqrt.as_ref().map(|a| a.view()),
        r2_linear: maps.r2_linear.as_ref().map(|a| a.view()),
        dark_offset: m.dark_offset,
        dark_var_dn2: run.dark_variance(),
        mono: m.layout() == "mono",
        summary: run.summary(),
    }
}
