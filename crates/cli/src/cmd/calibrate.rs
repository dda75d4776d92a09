//! `pgrf calibrate`: bias, dark and flat stacks in, a per-pixel calibration
//! file and a readable report out.

use crate::progress::Bar;
use anyhow::{Context, Result};
use clap::Args;
use pgrf_calib::{calibrate, CalibrateInput, CalibrationRun};
use pgrf_core::Progress;
use pgrf_raw::files::list_files;
use pgrf_report::{write_report, PtcPoint, ReportData, REPORT_FILES};
use std::path::PathBuf;

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
    let bias = list_files(&a.bias)?;
    let flat = list_files(&a.flat)?;
    let dark = match &a.dark {
        Some(d) => list_files(d)?,
        None => Vec::new(),
    };
    let inputs: Vec<&std::path::Path> = bias
        .iter()
        .chain(&flat)
        .chain(&dark)
        .map(|p| p.as_path())
        .collect();
    // The report goes into a folder (created if missing); every file it will
    // hold is checked with the calibration file, so nothing fails after the
    // whole calibration has run.
    let report_files: Vec<PathBuf> = match &a.report {
        Some(dir) => {
            if dir.exists() && !dir.is_dir() {
                anyhow::bail!(
                    "--report {} is a file; give a folder for the report",
                    dir.display()
                );
            }
            crate::output::require_parent_dir(dir).context("--report")?;
            // A folder that does not exist yet holds no input and no folder
            // in a report file's way; it is made after the calibration.
            if dir.is_dir() {
                REPORT_FILES.iter().map(|f| dir.join(f)).collect()
            } else {
                Vec::new()
            }
        }
        None => Vec::new(),
    };
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
    let (darktable_flag, darktable_file) = darktable_target(a);
    // The file to merge into is read before any work, so a malformed one
    // stops the run at once.
    let darktable_existing = match &a.darktable_into {
        Some(p) if p.exists() => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("--darktable-into {}", p.display()))?;
            pgrf_noise::darktable::NoiseProfiles::parse(&text, p).context("--darktable-into")?;
            Some(text)
        }
        _ => None,
    };
    let mut outputs = vec![
        ("-o", a.output.as_path()),
        (darktable_flag, darktable_file.as_path()),
    ];
    outputs.extend(report_files.iter().map(|p| ("--report", p.as_path())));
    crate::output::check_outputs(&outputs, &inputs)?;
    let total = bias.len() + flat.len() + dark.len();
    let bar = Bar::new("calibrating", total as u64, "frames", false);
    let run = calibrate(
        &CalibrateInput {
            bias: bias.clone(),
            dark: dark.clone(),
            flat: flat.clone(),
            iso: a.iso,
            tap_pixels: 4096,
            reject: a.reject,
            masters: a.masters.is_some(),
            temperature_tolerance: a.temperature_tolerance,
        },
        &bar,
    )?;
    bar.finish();
    // The darktable entry needs the camera's name and ISO, known now: made
    // (and refused) before anything is written.
    let darktable_text = darktable_entry(
        a,
        &run,
        darktable_existing.as_deref(),
        darktable_flag,
        &darktable_file,
    )?;
    if let Some(dir) = &a.masters {
        write_masters(dir, &run, &inputs, &a.output)?;
    }
    // The report first: the calibration file is the run's result, and it
    // appears only when everything else has been written.
    if let Some(dir) = &a.report {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create report folder", dir.display()))?;
        let files = write_report(dir, &report_data(&run))?;
        eprintln!("wrote report: {} files in {}", files.len(), dir.display());
    }
    if let Some((text, replaced, name)) = &darktable_text {
        pgrf_core::write_atomic(&darktable_file, text.as_bytes())
            .with_context(|| format!("{}", darktable_file.display()))?;
        let replacing = match replaced {
            0 => String::new(),
            n => format!(", replacing {n} entry of that camera at that ISO"),
        };
        eprintln!(
            "wrote {}: darktable noise-profile entry \"{name}\"{replacing} (darktable reads the file with: darktable --noiseprofiles {})",
            darktable_file.display(),
            darktable_file.display()
        );
    }
    run.calibration.save(&a.output)?;
    let m = &run.calibration.meta;
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
    if a.json {
        println!(
            "{}",
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
                "output": a.output.display().to_string(),
            })
        );
    }
    Ok(())
}

/// The master frames and the defect picture into `dir` (created if
/// missing), each checked against the inputs and `-o` before any is written.
fn write_masters(
    dir: &std::path::Path,
    run: &CalibrationRun,
    inputs: &[&std::path::Path],
    output: &std::path::Path,
) -> Result<()> {
    let ext = if run.key.fits { "fits" } else { "dng" };
    let files: Vec<PathBuf> = run
        .masters
        .iter()
        .map(|m| dir.join(format!("{}.{ext}", m.name)))
        .chain(std::iter::once(dir.join("defects.png")))
        .collect();
    if dir.is_dir() {
        let mut outputs = vec![("-o", output)];
        outputs.extend(files.iter().map(|f| ("--masters", f.as_path())));
        crate::output::check_outputs(&outputs, inputs)?;
    }
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create the masters folder", dir.display()))?;
    let meta = &run.calibration.meta;
    for (m, path) in run.masters.iter().zip(&files) {
        let written = if run.key.fits {
            m.fits(&run.key, meta.k, meta.temperature_c)
                .map_err(anyhow::Error::from)
                .and_then(|bytes| Ok(pgrf_core::write_atomic(path, &bytes)?))
        } else {
            pgrf_raw::write_dng(&m.frame(&run.key)?, path, &Default::default())
                .map_err(anyhow::Error::from)
        };
        written.with_context(|| format!("--masters {}", path.display()))?;
    }
    let key = &run.key;
    let picture = pgrf_raw::Preview {
        width: key.width,
        height: key.height,
        rgb: pgrf_calib::masters::defect_picture(&run.calibration.maps.defects, key),
        warnings: Vec::new(),
    };
    picture.write_png(files.last().expect("defects.png"), 8)?;
    eprintln!(
        "wrote {} master frames and defects.png in {}",
        run.masters.len(),
        dir.display()
    );
    Ok(())
}

/// Where the darktable entry goes, and the flag that named it in messages:
/// `--darktable-into`, else beside `-o`.
fn darktable_target(a: &CalibrateArgs) -> (&'static str, PathBuf) {
    match &a.darktable_into {
        Some(p) => ("--darktable-into", p.clone()),
        None => (
            "-o (its darktable entry)",
            a.output.with_extension("noiseprofiles.json"),
        ),
    }
}

/// The text of the darktable file with the calibrated camera's entry
/// (`pgrf_noise::darktable::Export`), how many entries it replaced and the
/// entry's name; None (with a note) when the frames carry no ISO and no
/// file was asked for.
fn darktable_entry(
    a: &CalibrateArgs,
    run: &CalibrationRun,
    existing: Option<&str>,
    flag: &str,
    path: &std::path::Path,
) -> Result<Option<(String, usize, String)>> {
    let m = &run.calibration.meta;
    let maker = a.darktable_maker.clone().unwrap_or_else(|| m.make.clone());
    let model = a.darktable_model.clone().unwrap_or_else(|| m.model.clone());
    // darktable finds an entry by maker, model and ISO; frames without them
    // (FITS from an astronomy camera names no maker) get no entry unless
    // one was asked for.
    let missing = if m.iso.is_none() {
        Some("record no ISO (give --iso)")
    } else if maker.trim().is_empty() || model.trim().is_empty() {
        Some("name no camera maker or model (give --darktable-maker and --darktable-model)")
    } else {
        None
    };
    if let Some(what) = missing {
        if a.darktable_into.is_some() {
            anyhow::bail!(
                "--darktable-into {}: the frames {what}, and darktable finds a profile by maker, model and ISO",
                path.display()
            );
        }
        eprintln!("pgrf: note: the frames {what}: no darktable noise profile written");
        return Ok(None);
    }
    let iso = m.iso.expect("checked above");
    let [s, o] = run.noise_profile();
    let export = pgrf_noise::darktable::Export {
        maker,
        model,
        iso,
        s,
        o,
        comment: format!(
            "measured by pgrf calibrate: K {:.4} DN/e-, photosite variance S x + O on [0, 1] with S {s:.6e}, O {o:.6e}; a, b = S, O / {} (darktable's PPG profiling chain)",
            m.k,
            pgrf_noise::darktable::VARIANCE_FACTOR
        ),
    };
    let (text, replaced) = export
        .merge_into(existing, path)
        .with_context(|| format!("{flag} {}", path.display()))?;
    Ok(Some((text, replaced, export.entry_name())))
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
