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
use pgrf_nn::infer::enhance::{
    describe_method, enhance_file, BoxError, CalibrationFile, EnhanceConfig, FileReport, Job,
    RatioChoice,
};
use pgrf_nn::infer::{Restore, SamplerChoice, Tiling};
use std::path::PathBuf;

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

/// Refuse flag values no file can make right, before any work.
fn check_flags(a: &EnhanceArgs) -> Result<()> {
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
    Ok(pgrf_nn::infer::check_tiling_args(a.tile, a.overlap)?)
}

/// How every file is enhanced (the calibration loaded).
fn config(a: &EnhanceArgs) -> Result<EnhanceConfig> {
    let calib = match &a.calib {
        Some(p) => Some(CalibrationFile {
            path: p.clone(),
            calibration: Calibration::load(p).context("--calib")?,
        }),
        None => None,
    };
    let ratio = match (a.ratio, a.target_exposure) {
        (Some(r), _) => RatioChoice::Fixed(r),
        (None, Some(seconds)) => RatioChoice::TargetExposure {
            seconds,
            iso: a.target_iso,
        },
        (None, None) => unreachable!("checked in check_flags"),
    };
    Ok(EnhanceConfig {
        ratio,
        calib,
        force: a.force,
        tiling: Tiling {
            tile: a.tile,
            overlap: a.overlap,
            seed: a.seed,
            device: a.device,
        },
    })
}

/// The model, the device and what the user should know about them; printed
/// before the first image is processed, so that an input that fails at
/// once still gives a single line.
fn print_header(a: &EnhanceArgs, restorer: &dyn Restore) {
    eprintln!(
        "model: {}; device {}",
        describe_method(restorer),
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

pub fn run(a: &EnhanceArgs) -> Result<()> {
    check_flags(a)?;
    let jobs = plan_jobs(a)?;
    a.device.check_available().map_err(anyhow::Error::msg)?;
    let cfg = config(a)?;
    let choice = SamplerChoice {
        kind: a.sampler,
        t2: a.t2,
        samples: a.samples,
    };
    let restorer = crate::shipped::load_model(&a.model, choice, a.device)
        .with_context(|| format!("--model {}", a.model.display()))?;
    let header = std::cell::Cell::new(a.quiet);
    let print_header = || {
        if !header.replace(true) {
            print_header(a, restorer.as_ref());
        }
    };
    let mut failed: Vec<(PathBuf, String)> = Vec::new();
    let n = jobs.len();
    for (i, job) in jobs.iter().enumerate() {
        match enhance_one(a, &cfg, job, restorer.as_ref(), (i, n), &print_header) {
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

/// The inputs: files as given, folders expanded; and whether a folder was
/// among them.
fn expand_inputs(a: &EnhanceArgs) -> Result<(Vec<PathBuf>, bool)> {
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
    Ok((inputs, had_dir))
}

/// Expand folders, decide every output path, and check that the outputs can
/// be written before any work starts.
fn plan_jobs(a: &EnhanceArgs) -> Result<Vec<Job>> {
    let (mut inputs, had_dir) = expand_inputs(a)?;
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
    folder_jobs(a, inputs)
}

/// One job per input into the output folder (created if missing), keeping
/// the input's name with a .dng extension.
fn folder_jobs(a: &EnhanceArgs, inputs: Vec<PathBuf>) -> Result<Vec<Job>> {
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

/// Enhance file number `index` of `count` and say what was written.
fn enhance_one(
    a: &EnhanceArgs,
    cfg: &EnhanceConfig,
    job: &Job,
    restorer: &dyn Restore,
    (index, count): (usize, usize),
    print_header: &dyn Fn(),
) -> Result<FileReport> {
    let name = job
        .input
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let open = |p: &std::path::Path| a.input.open(p).map_err(BoxError::from);
    let start = || {
        print_header();
        Bar::new(
            format!("[{}/{count}] {name}", index + 1),
            0,
            "tiles",
            a.quiet,
        )
    };
    let r = enhance_file(cfg, restorer, job, open, start)?;
    if !a.quiet {
        eprintln!(
            "wrote {}{}: {}x{}, ratio {:.1}, {} tile{} of {}, {:.1} s{}",
            r.output,
            r.png
                .as_ref()
                .map(|p| format!(" and {p}"))
                .unwrap_or_default(),
            r.width,
            r.height,
            r.ratio,
            r.tiles,
            if r.tiles == 1 { "" } else { "s" },
            r.tile,
            r.seconds,
            if r.defects_corrected > 0 {
                format!(
                    ", {} defective pixels corrected from their neighbours",
                    r.defects_corrected
                )
            } else {
                String::new()
            },
        );
    }
    Ok(r)
}
