//! `pgrf calibrate`: bias, dark and flat stacks in, a per-pixel calibration
//! file and a readable report out.

use anyhow::{Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use pgrf_calib::report::{write_report, PtcPoint, ReportData};
use pgrf_calib::stack::list_files;
use pgrf_calib::{calibrate, CalibrateInput, CalibrationRun};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct CalibrateArgs {
    /// Folder of bias frames (shortest exposure, lens capped).
    #[arg(long)]
    pub bias: PathBuf,
    /// Folder of dark frames (lens capped, two or more exposure times, read from EXIF).
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
}

pub fn run(a: &CalibrateArgs) -> Result<()> {
    let bias = list_files(&a.bias)?;
    let flat = list_files(&a.flat)?;
    let dark = match &a.dark {
        Some(d) => list_files(d)?,
        None => Vec::new(),
    };
    if let Some(dir) = a.output.parent().filter(|p| !p.as_os_str().is_empty()) {
        anyhow::ensure!(
            dir.is_dir(),
            "{}: folder '{}' does not exist",
            a.output.display(),
            dir.display()
        );
    }
    let total = bias.len() + flat.len() + dark.len();
    let bar = ProgressBar::new(total as u64).with_style(
        ProgressStyle::with_template(
            "{spinner} calibrating {pos}/{len} frames [{bar:30}] {per_sec} eta {eta}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    let run = calibrate(
        &CalibrateInput {
            bias,
            dark,
            flat,
            iso: a.iso,
            tap_pixels: 4096,
        },
        &|| bar.inc(1),
    )?;
    bar.finish_and_clear();
    run.calibration.save(&a.output)?;
    let m = &run.calibration.meta;
    eprintln!(
        "wrote {}: K {:.4} DN/e- ({}), read sigma median {:.3} DN, row sigma {:.3} DN, DSNU {:.3} DN, dark law {}, {} hot / {} dead pixels",
        a.output.display(),
        m.k,
        m.k_method,
        m.read_sigma_median,
        m.row_sigma,
        m.dsnu,
        m.dark_law,
        m.hot_pixels,
        m.dead_pixels
    );
    if let Some(dir) = &a.report {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create report folder", dir.display()))?;
        let files = write_report(dir, &report_data(&run))?;
        eprintln!("wrote report: {} files in {}", files.len(), dir.display());
    }
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
                "dark_law": m.dark_law,
                "dark_r2_sqrt": m.dark_r2_sqrt,
                "dark_r2_linear": m.dark_r2_linear,
                "dark_rate_mean": m.dark_rate_mean,
                "hot_pixels": m.hot_pixels,
                "dead_pixels": m.dead_pixels,
                "output": a.output.display().to_string(),
            })
        );
    }
    Ok(())
}

fn report_data(run: &CalibrationRun) -> ReportData<'_> {
    let m = &run.calibration.meta;
    let maps = &run.calibration.maps;
    let row = |q: &str, v: String, u: &str| (q.to_string(), v, u.to_string());
    let mut summary = vec![
        row(
            "System gain K",
            format!("{:.4} ({})", m.k, m.k_method),
            "DN/e-",
        ),
        row(
            "Inverse system gain 1/K",
            format!("{:.4}", 1.0 / m.k),
            "e-/DN",
        ),
        row(
            "System gain, eq. 3.15 at the brightest level",
            format!("{:.4}", run.gain.k_var_mean),
            "DN/e-",
        ),
        row(
            "Temporal dark noise (median per-pixel read sigma)",
            format!(
                "{:.3} ({:.3} e-)",
                m.read_sigma_median,
                m.read_sigma_median / m.k
            ),
            "DN",
        ),
        row("Row noise sigma", format!("{:.3}", m.row_sigma), "DN"),
        row(
            "DSNU (spatial sd of the dark offset)",
            format!("{:.3} ({:.3} e-)", m.dsnu, m.dsnu / m.k),
            "DN",
        ),
        row(
            "PRNU (spatial sd of the response / mean)",
            m.prnu
                .map(|p| format!("{:.3}", 100.0 * p))
                .unwrap_or_else(|| "-".into()),
            "%",
        ),
    ];
    match (m.dark_rate_mean, m.dark_r2_sqrt, m.dark_r2_linear) {
        (Some(rate), Some(rs), Some(rl)) => {
            let unit = if m.dark_law == "linear" {
                "e-/s"
            } else {
                "e-/sqrt(s)"
            };
            summary.push(row(
                &format!("Dark current (mean, {} law)", m.dark_law),
                format!("{rate:.4}"),
                unit,
            ));
            summary.push(row(
                "Dark signal fit R^2, a*sqrt(t) / a*t",
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
    summary.push(row(
        "Hot / dead pixels",
        format!("{} / {}", m.hot_pixels, m.dead_pixels),
        "pixels",
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
        sigma_read: maps["sigma_read"].view(),
        fixed_pattern: maps["fixed_pattern"].view(),
        r2_sqrt: maps.get("r2_sqrt").map(|a| a.view()),
        r2_linear: maps.get("r2_linear").map(|a| a.view()),
        summary,
    }
}
