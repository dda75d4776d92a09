//! `pgrf enhance`: dark noisy RAW photos in, clean linear DNGs (and sRGB
//! previews) out, with either network, at full resolution in bounded memory.

use crate::input::InputArgs;
use crate::output::{require_parent_dir, same_file};
use crate::progress::Bar;
use anyhow::{bail, Context, Result};
use clap::Args;
use pgrf_calib::Calibration;
use pgrf_nn::backend::DeviceKind;
use pgrf_nn::flow::sample::SamplerKind;
use pgrf_nn::infer::prepare::ratio_from_exposure;
use pgrf_nn::infer::restorer::describe_sampler;
use pgrf_nn::infer::{restore_frame, Restore, SamplerChoice, Tiling};
use pgrf_raw::{render_preview, write_dng, DngOptions, PreviewOptions};
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct EnhanceArgs {
    /// Noisy RAW files, or folders of them.
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// Weight file from `pgrf train` (SPC denoiser or PGRF flow model).
    #[arg(long, short = 'm')]
    pub model: PathBuf,
    /// Exposure ratio: the input is multiplied by it before denoising.
    #[arg(long, conflicts_with = "target_exposure", allow_hyphen_values = true)]
    pub ratio: Option<f32>,
    /// Instead of --ratio: the exposure (seconds) to brighten to; the ratio is
    /// target / the file's exposure time (x --target-iso / the file's ISO).
    #[arg(long)]
    pub target_exposure: Option<f64>,
    /// With --target-exposure: the ISO of the target exposure (default: the file's).
    #[arg(long, requires = "target_exposure")]
    pub target_iso: Option<u32>,
    /// Calibration file (`pgrf calibrate`): subtract its fixed pattern and
    /// mean dark current before amplifying.
    #[arg(long)]
    pub calib: Option<PathBuf>,
    /// Apply a calibration of another camera or ISO anyway.
    #[arg(long)]
    pub force: bool,
    /// Output DNG (one input file), or folder for the results (created if its
    /// parent exists); files keep their names with a .dng extension.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Also write an sRGB preview: to this .png with one input, next to each
    /// DNG without a value.
    #[arg(long, num_args = 0..=1)]
    #[allow(clippy::option_option)]
    pub png: Option<Option<PathBuf>>,
    /// Tile side in packed pixels, at least 144 when the frame is tiled (default: from available memory on the CPU, 1024 on CUDA).
    #[arg(long)]
    pub tile: Option<usize>,
    /// Minimum overlap of neighbouring tiles, packed pixels, at least 64 [default: 64].
    #[arg(long)]
    pub overlap: Option<usize>,
    /// cpu, or cuda (needs a build with `--features cuda`).
    #[arg(long, default_value = "cpu")]
    pub device: DeviceKind,
    /// Flow model sampler: two-stage (the paper's, 2 evaluations), one-step, or euler:N.
    #[arg(long, default_value = "two-stage")]
    pub sampler: SamplerKind,
    /// Second time of the two-stage sampler (default: the file's searched t2).
    #[arg(long, allow_hyphen_values = true)]
    pub t2: Option<f32>,
    /// Flow model: average this many samples from different start noise.
    #[arg(long, default_value_t = 1)]
    pub samples: usize,
    /// Seed of the flow model's start noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// One JSON line per file on stdout.
    #[arg(long)]
    pub json: bool,
    /// No progress bar or notes.
    #[arg(long, short)]
    pub quiet: bool,
    #[command(flatten)]
    pub input: InputArgs,
}

#[derive(Serialize)]
struct FileReport {
    input: String,
    output: String,
    png: Option<String>,
    width: usize,
    height: usize,
    ratio: f32,
    method: String,
    nfe: usize,
    tile: usize,
    tiles: usize,
    /// Pixels the calibration's defect map replaced (cosmetic correction).
    defects_corrected: usize,
    seconds: f64,
    peak_rss_mib: Option<f64>,
}

/// Where one input's results go.
struct Job {
    input: PathBuf,
    output: PathBuf,
    png: Option<PathBuf>,
}

pub fn run(a: &EnhanceArgs) -> Result<()> {
    if let Some(r) = a.ratio {
        if !(r.is_finite() && r > 0.0) {
            bail!("--ratio must be a positive number, got {r}");
        }
    }
    if a.ratio.is_none() && a.target_exposure.is_none() {
        bail!(
            "give the exposure ratio (--ratio R) or a target exposure (--target-exposure SECONDS)"
        );
    }
    if let Some(t) = a.t2 {
        if !(0.0..=1.0).contains(&t) {
            bail!("--t2 must be in [0, 1], got {t}");
        }
    }
    pgrf_nn::infer::check_tiling_args(a.tile, a.overlap)?;
    let jobs = plan_jobs(a)?;
    a.device.check_available().map_err(anyhow::Error::msg)?;
    let calib = match &a.calib {
        Some(p) => Some(Calibration::load(p).context("--calib")?),
        None => None,
    };
    let choice = SamplerChoice {
        kind: a.sampler,
        t2: a.t2,
        samples: a.samples,
    };
    let restorer = crate::shipped::load_model(&a.model, choice, a.device)
        .with_context(|| format!("--model {}", a.model.display()))?;
    let method = format!(
        "{} ({})",
        restorer.meta().arch.describe(),
        describe_sampler(restorer.as_ref())
    );
    // Printed before the first image is processed, so that an input that
    // fails at once still gives a single line.
    let header = std::cell::Cell::new(a.quiet);
    let print_header = || {
        if !header.replace(true) {
            eprintln!(
                "model: {method}; device {}",
                pgrf_nn::backend::describe(a.device)
            );
            if restorer.sampler().is_some() && restorer.meta().t2.is_none() && a.t2.is_none() {
                eprintln!(
                    "note: {} has no searched t2; using {} (run `pgrf search` to find the best)",
                    a.model.display(),
                    pgrf_nn::infer::restorer::UNSEARCHED_T2
                );
            }
            if restorer.meta().noise.calibrated_dark_level && a.calib.is_none() {
                eprintln!(
                    "note: {} learned calibrated captures (dark level subtracted); without --calib \
the file's black level is taken as exact, and an error in it tints dark areas",
                    a.model.display()
                );
            }
        }
    };
    let mut failed: Vec<(PathBuf, String)> = Vec::new();
    let n = jobs.len();
    for (i, job) in jobs.iter().enumerate() {
        match enhance_one(
            a,
            job,
            restorer.as_ref(),
            calib.as_ref(),
            &method,
            i,
            n,
            &print_header,
        ) {
            Ok(report) => {
                if a.json {
                    println!("{}", serde_json::to_string(&report)?);
                }
            }
            Err(e) => {
                let msg = format!("{e:#}").replace('\n', " ");
                if n == 1 {
                    bail!(msg);
                }
                if !a.quiet {
                    eprintln!("skipped {}: {msg}", job.input.display());
                }
                if a.json {
                    println!(
                        "{}",
                        serde_json::json!({"input": job.input.display().to_string(), "error": msg})
                    );
                }
                failed.push((job.input.clone(), msg));
            }
        }
    }
    if !failed.is_empty() {
        let list: Vec<String> = failed
            .iter()
            .map(|(p, _)| p.display().to_string())
            .collect();
        bail!(
            "{} of {n} files could not be enhanced: {}",
            failed.len(),
            list.join(", ")
        );
    }
    Ok(())
}

/// Expand folders, decide every output path, and check that the outputs can
/// be written before any work starts.
fn plan_jobs(a: &EnhanceArgs) -> Result<Vec<Job>> {
    let mut inputs = Vec::new();
    let mut had_dir = false;
    for p in &a.inputs {
        if p.is_dir() {
            had_dir = true;
            inputs.extend(pgrf_raw::files::list_files(p)?);
        } else if p.is_file() {
            inputs.push(p.clone());
        } else {
            bail!("{}: no such file or folder", p.display());
        }
    }
    let single = inputs.len() == 1 && !had_dir;
    let is_dng = a
        .output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("dng"));
    let png_path = a.png.as_ref().and_then(|p| p.as_ref());
    if let Some(p) = png_path {
        if !p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")) {
            bail!(
                "--png {}: expected a .png path (give --png after the input files, or without a value to write previews next to the DNGs)",
                p.display()
            );
        }
        if !single {
            bail!("--png PATH names one preview; with several inputs give --png without a value");
        }
        require_parent_dir(p)?;
    }
    if single && is_dng {
        require_parent_dir(&a.output)?;
        if same_file(&a.output, &inputs[0]) {
            bail!(
                "-o {} is the input file; write the result elsewhere",
                a.output.display()
            );
        }
        let png = a
            .png
            .as_ref()
            .map(|p| p.clone().unwrap_or_else(|| a.output.with_extension("png")));
        return Ok(vec![Job {
            input: inputs.remove(0),
            output: a.output.clone(),
            png,
        }]);
    }
    if is_dng {
        bail!(
            "-o {}: several inputs need an output folder, not a .dng file",
            a.output.display()
        );
    }
    if !a.output.is_dir() {
        require_parent_dir(&a.output)?;
        std::fs::create_dir(&a.output)
            .with_context(|| format!("creating output folder {}", a.output.display()))?;
    }
    let mut seen = std::collections::HashSet::new();
    inputs
        .into_iter()
        .map(|input| {
            let stem = input
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "out".into());
            let output = a.output.join(format!("{stem}.dng"));
            if !seen.insert(output.clone()) {
                bail!(
                    "two inputs would both be written to {} (same name in different folders)",
                    output.display()
                );
            }
            if same_file(&output, &input) {
                bail!(
                    "{} would overwrite its input; choose another output folder",
                    output.display()
                );
            }
            let png = a.png.as_ref().map(|_| output.with_extension("png"));
            Ok(Job { input, output, png })
        })
        .collect()
}

#[allow(clippy::too_many_arguments)]
fn enhance_one(
    a: &EnhanceArgs,
    job: &Job,
    restorer: &dyn Restore,
    calib: Option<&Calibration>,
    method: &str,
    index: usize,
    count: usize,
    print_header: &dyn Fn(),
) -> Result<FileReport> {
    let t0 = Instant::now();
    let mut frame = a.input.open(&job.input)?;
    frame
        .require_cfa("pgrf enhance (its denoisers learned Bayer data)")
        .with_context(|| format!("{}", job.input.display()))?;
    let ratio = match (a.ratio, a.target_exposure) {
        (Some(r), _) => r,
        (None, Some(t)) => ratio_from_exposure(&frame, t, a.target_iso)?,
        (None, None) => unreachable!("checked in run"),
    };
    let mut defects_fixed = 0;
    let dark = match (calib, &a.calib) {
        (Some(cal), Some(path)) => {
            cal.check_matches(&frame.make, &frame.model, frame.iso, a.force)
                .and_then(|()| cal.check_layout(&frame))
                .with_context(|| format!("--calib {}", path.display()))?;
            if (cal.meta.width, cal.meta.height) != (frame.width, frame.height) {
                bail!(
                    "--calib {}: calibration is {}x{}, the photo {}x{}",
                    path.display(),
                    cal.meta.width,
                    cal.meta.height,
                    frame.width,
                    frame.height
                );
            }
            let shading = cal.dark_shading_dn(frame.exposure_s.unwrap_or(0.0))?;
            defects_fixed = cal.correct_defects(&mut frame);
            Some(shading)
        }
        _ => None,
    };
    let tiling = Tiling {
        tile: a.tile,
        overlap: a.overlap,
        seed: a.seed,
        device: a.device,
    };
    print_header();
    let name = job
        .input
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let bar = Bar::new(
        format!("[{}/{count}] {name}", index + 1),
        0,
        "tiles",
        a.quiet,
    );
    let mut restored = restore_frame(restorer, &frame, ratio, dark.as_ref(), &tiling, &bar)?;
    let (tiles, tile) = (restored.packed.plan.count(), restored.packed.tile_side());
    // The input's NoiseProfile describes the noisy input; what noise a
    // network leaves is not known, so the output states none.
    restored.frame.noise_profile = None;
    write_dng(&restored.frame, &job.output, &DngOptions::default())?;
    if let Some(png) = &job.png {
        render_preview(&restored.frame, &PreviewOptions::default())?.write_png(png, 8)?;
    }
    let seconds = t0.elapsed().as_secs_f64();
    if !a.quiet {
        eprintln!(
            "wrote {}{}: {}x{}, ratio {ratio:.1}, {tiles} tile{} of {}, {seconds:.1} s{}",
            job.output.display(),
            job.png
                .as_ref()
                .map(|p| format!(" and {}", p.display()))
                .unwrap_or_default(),
            frame.width,
            frame.height,
            if tiles == 1 { "" } else { "s" },
            tile,
            if defects_fixed > 0 {
                format!(", {defects_fixed} defective pixels corrected from their neighbours")
            } else {
                String::new()
            },
        );
    }
    Ok(FileReport {
        input: job.input.display().to_string(),
        output: job.output.display().to_string(),
        png: job.png.as_ref().map(|p| p.display().to_string()),
        width: frame.width,
        height: frame.height,
        ratio,
        method: method.to_string(),
        nfe: restorer.nfe(),
        tile,
        tiles,
        defects_corrected: defects_fixed,
        seconds,
        peak_rss_mib: pgrf_core::mem::peak_rss_mib(),
    })
}
