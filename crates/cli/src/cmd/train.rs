//! `pgrf train denoiser|flow`: every setting can come from a TOML file
//! (`--config`, flat keys named like the flags with underscores) and any flag
//! overrides the file. Progress bar, Ctrl-C (checkpoint and exit), and a JSON
//! summary line for scripts.

use anyhow::{bail, Context, Result};
use clap::Args;

use pgrf_calib::Calibration;
use pgrf_nn::backend::DeviceKind;
use pgrf_nn::data::validation::ValSet;
use pgrf_nn::schedule::Schedule;
use pgrf_nn::train::{Outcome, TrainSettings};
use pgrf_nn::weights::NoiseSource;
use pgrf_nn::{Method, TrainConfig};
use pgrf_noise::mix::PairMix;
use pgrf_noise::pair::RatioSpec;
use pgrf_noise::ModelKind;
use serde::Serialize;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// The flags of every setting, all optional: the ones given override the
/// `--config` file, which overrides `TrainConfig`'s defaults (serialised as a
/// TOML table, unset flags are left out).
#[derive(Args, Debug, Default, Clone, Serialize)]
pub struct Settings {
    /// Clean training images, comma-separated entries `SOURCE[@WEIGHT]`: a folder (or file) of clean RAWs, a folder of photos (JPEG/PNG/TIFF, unprocessed into the camera's RAW space), or "procedural" (dead-leaves scenes); crops are drawn in proportion to the weights (default 1 each), e.g. `photos/@3,procedural@1` [default: procedural].
    #[arg(long)]
    pub data: Option<String>,
    /// Validation images, entries as --data (default: 10% of each folder's files held out; procedural entries validate on procedural scenes).
    #[arg(long)]
    pub val_data: Option<String>,
    /// The camera photos are unprocessed into: any RAW file of it (colour matrix, white balance, CFA, levels) [default: the built-in A7S2's with the sony-a7s2 profile].
    #[arg(long)]
    pub camera_like: Option<PathBuf>,
    /// Photos: downscale factor per side before cropping (area filter; removes JPEG and demosaicing artefacts) [default: 2].
    #[arg(long)]
    pub photo_downscale: Option<usize>,
    /// Photos: invert a global S-shaped tone curve (Brooks et al.'s smoothstep) before the sRGB transfer.
    #[arg(long, num_args = 0..=1, default_missing_value = "true")]
    pub photo_inverse_tone: Option<bool>,
    /// Photos: largest factor by which each crop's red and blue white-balance multipliers are varied (log-uniform in [1/S, S]); 1.25 spans one camera's daylight, shade and flash, 2.5 reaches cameras whose raw channels are nearly balanced [default: 1.25].
    #[arg(long)]
    pub photo_wb_spread: Option<f32>,
    /// Camera noise profile (built-in name, darktable:"MAKER MODEL", dng:FILE.dng or JSON path), or a mix `NAME[@WEIGHT],...` where each crop draws one camera's noise, e.g. sony-a7s2@3,nikon-d850@1; --iso/--iso-range are the first profile's, and become a gain range the others share [default: sony-a7s2].
    #[arg(long)]
    pub profile: Option<String>,
    /// Per-pixel calibration file (from `pgrf calibrate`) for the pgrf noise model.
    #[arg(long)]
    pub calib: Option<PathBuf>,
    /// Noise model of the synthetic pairs: pg, eld or pgrf [default: pgrf].
    #[arg(long)]
    pub noise: Option<ModelKind>,
    /// Fixed ISO (default: parameters drawn from the profile's ELD distribution).
    #[arg(long)]
    pub iso: Option<u32>,
    /// Draw the gain between two ISOs only, e.g. 800,6400 (default: the profile's whole range).
    #[arg(long, value_delimiter = ',')]
    pub iso_range: Option<Vec<u32>>,
    /// Smallest exposure ratio [default: 1].
    #[arg(long)]
    pub ratio_min: Option<f32>,
    /// Largest exposure ratio [default: 300].
    #[arg(long)]
    pub ratio_max: Option<f32>,
    /// Side of the packed training crops [default: 512].
    #[arg(long)]
    pub patch: Option<usize>,
    /// Crops per step [default: 1].
    #[arg(long)]
    pub batch: Option<usize>,
    /// Data worker threads [default: 2].
    #[arg(long)]
    pub workers: Option<usize>,
    /// Memory for decoded training RAWs, MiB [default: 4096].
    #[arg(long)]
    pub cache_mib: Option<usize>,
    /// Optimisation steps [default: 30000].
    #[arg(long)]
    pub steps: Option<u64>,
    /// Base learning rate [default: 1e-4].
    #[arg(long)]
    pub lr: Option<f64>,
    /// Learning-rate schedule: eld (1/2 at 50%, 1/10 at 90%), constant or cosine [default: eld].
    #[arg(long)]
    pub schedule: Option<Schedule>,
    /// Clip each parameter's gradient to this norm.
    #[arg(long)]
    pub clip_grad: Option<f32>,
    /// Seed of initialisation, crops, noise, X0 and t [default: 0].
    #[arg(long)]
    pub seed: Option<u64>,
    /// Turn off flips and transposes.
    #[arg(long, num_args = 0..=1, default_missing_value = "true")]
    pub no_augment: Option<bool>,
    /// Train on captures without the camera's dark-level offset (black-level error, colour bias): for input calibrated by `pgrf enhance --calib` (or the synthetic protocol); recorded in the weight file.
    #[arg(long, num_args = 0..=1, default_missing_value = "true")]
    pub calibrated_dark_level: Option<bool>,
    /// Width of the first level: SID U-Net channels [default: 32]; for the flow model the SR3 inner channels unless --inner-channels is given.
    #[arg(long)]
    pub width: Option<usize>,
    /// Learn a correction: the SID U-Net adds its input to its output; the flow model adds T - Xt to its velocity (its first stage starts as the noisy input). Not the papers' design; converges far faster for small CPU-trained models.
    #[arg(long, num_args = 0..=1, default_missing_value = "true")]
    pub residual: Option<bool>,
    /// Start from this weight file's weights (a trained network of exactly this configuration, e.g. models/spc.safetensors) instead of fresh ones: fine-tuning on other data or conditions; the optimiser and the learning-rate schedule start afresh, and the output records the file and its training.
    #[arg(long)]
    pub init: Option<PathBuf>,
    /// SR3 channels of the first level [default: 64, or --width].
    #[arg(long)]
    pub inner_channels: Option<usize>,
    /// SR3 channel multipliers per level, comma-separated [default: 1,2,4,8,8].
    #[arg(long, value_delimiter = ',')]
    pub channel_mults: Option<Vec<usize>>,
    /// SR3 residual blocks per level [default: 2].
    #[arg(long)]
    pub res_blocks: Option<usize>,
    /// SR3 levels with self-attention (0 = full resolution), comma-separated [default: 3].
    #[arg(long, value_delimiter = ',')]
    pub attn_levels: Option<Vec<usize>>,
    /// SR3 GroupNorm groups [default: 32, or fewer to divide the channels].
    #[arg(long)]
    pub norm_groups: Option<usize>,
    /// SR3 dropout [default: 0].
    #[arg(long)]
    pub dropout: Option<f64>,
    /// Validate every N steps (0: only at the end) [default: 1000].
    #[arg(long)]
    pub val_every: Option<u64>,
    /// Validation pairs [default: 4].
    #[arg(long)]
    pub val_pairs: Option<usize>,
    /// Side of the validation crops [default: min(patch, 256)].
    #[arg(long)]
    pub val_patch: Option<usize>,
    /// t2 of the two-stage sampler when validating the flow model [default: 0.5].
    #[arg(long)]
    pub val_t2: Option<f32>,
    /// Flow model: draw the training time t from U(0, TIME_MAX) instead of U(0, 1) (Algorithm 1), in (0, 1]: spend the training on the times the two-stage sampler uses (t = 0 and t2), e.g. 0.5; recorded in the weight file [default: 1].
    #[arg(long)]
    pub time_max: Option<f32>,
    /// Checkpoint every N steps [default: 1000].
    #[arg(long)]
    pub checkpoint_every: Option<u64>,
    /// Checkpoint file [default: OUTPUT with extension .ckpt].
    #[arg(long)]
    pub checkpoint: Option<PathBuf>,
    /// Log file, CSV (or JSON lines if it ends in .jsonl) [default: OUTPUT with extension .log.csv].
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Log the mean loss every N steps [default: 10].
    #[arg(long)]
    pub log_every: Option<u64>,
    /// Weight file to write.
    #[arg(short = 'o', long = "output")]
    pub output: Option<PathBuf>,
    /// cpu or cuda [default: cpu].
    #[arg(long)]
    pub device: Option<DeviceKind>,
}

#[derive(Args, Debug)]
pub struct TrainArgs {
    /// What to train: spc (the SID U-Net denoiser; also `denoiser`) or pgrf
    /// (the flow model's SR3 velocity field; also `flow`).
    pub method: Method,
    /// TOML file of settings (keys as the flags, with underscores); flags override it.
    #[arg(long)]
    pub config: Option<PathBuf>,
    #[command(flatten)]
    pub settings: Settings,
    /// Continue from the checkpoint (same settings; --steps may grow).
    #[arg(long)]
    pub resume: bool,
    /// Print one JSON summary line at the end.
    #[arg(long)]
    pub json: bool,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Print the merged configuration as TOML (a `--config` file) and exit.
    #[arg(long)]
    pub print_config: bool,
}

/// The configuration: defaults, then the `--config` file, then the flags.
fn merged(a: &TrainArgs) -> Result<TrainConfig> {
    let file = match &a.config {
        None => TrainConfig::default(),
        Some(p) => {
            let text = std::fs::read_to_string(p).with_context(|| format!("{}", p.display()))?;
            TrainConfig::from_toml(&text).with_context(|| format!("{}", p.display()))?
        }
    };
    let c = file.overlay(&a.settings)?;
    c.validate()?;
    if a.method == Method::Spc && c.time_max != 1.0 {
        bail!("--time-max is the flow model's training time range; the SPC denoiser has none");
    }
    Ok(c)
}

pub fn run(a: &TrainArgs) -> Result<()> {
    let s = merged(a)?;
    if a.print_config {
        print!("{}", s.to_toml());
        return Ok(());
    }
    let Some(out) = s.output.clone() else {
        bail!("no output: give -o FILE.safetensors (or `output = ...` in the config)");
    };
    // Every file the run writes, checked before any work: folders exist,
    // none is a folder or one of the run's inputs, no two are the same.
    let checkpoint_path = s
        .checkpoint
        .clone()
        .unwrap_or_else(|| out.with_extension("ckpt"));
    let log_path = s
        .log
        .clone()
        .unwrap_or_else(|| out.with_extension("log.csv"));
    let data_files: Vec<PathBuf> = pgrf_nn::data::build::parse_data(&s.data)
        .map(|entries| entries.into_iter().filter_map(|e| e.path).collect())
        .unwrap_or_default();
    let mut inputs: Vec<&std::path::Path> = data_files.iter().map(|p| p.as_path()).collect();
    inputs.extend(s.calib.as_deref());
    inputs.extend(s.camera_like.as_deref());
    inputs.extend(s.init.as_deref());
    crate::output::check_outputs(
        &[
            ("-o", &out),
            ("--checkpoint", &checkpoint_path),
            ("--log", &log_path),
        ],
        &inputs,
    )?;
    let device = s.device;
    device.check_available().map_err(anyhow::Error::msg)?;
    let arch = s.architecture(a.method)?;
    if let Some(init) = &s.init {
        pgrf_nn::weights::require_arch(init, &arch)?;
    }
    {
        use pgrf_nn::infer::memory::{tile_bytes, training_bytes};
        let (p, b, v) = (s.patch, s.batch, s.val_patch());
        let need = training_bytes(&arch, p, b).max(tile_bytes(&arch, v, v));
        pgrf_core::mem::check_fits(
            &format!("training with --patch {p} --batch {b} (validation crops {v})"),
            need,
        )
        .map_err(|e| anyhow::anyhow!("{e}; give a smaller --patch, --batch or --val-patch"))?;
    }
    let (patch, batch) = (s.patch, s.batch);
    let val_patch = s.val_patch();
    let steps = s.steps;
    let schedule = s.schedule;
    let model = s.noise;
    let profile_name = s.profile.clone();
    let (lo, hi) = (s.ratio_min, s.ratio_max);
    let iso_range = s.iso_range()?;
    let mut mix = PairMix::build(
        &profile_name,
        model,
        s.iso,
        iso_range,
        RatioSpec::Uniform { lo, hi },
    )
    .context("--profile")?;
    mix.set_calibrated_dark_level(s.calibrated_dark_level);
    let mut calibration = None;
    if let Some(path) = &s.calib {
        let described = mix.describe();
        let Some(spec) = mix.single_mut() else {
            bail!(
                "--calib {} describes one sensor; it cannot go with a mix of profiles ({described})",
                path.display(),
            );
        };
        let cal = Calibration::load(path)?;
        cal.apply_to(spec)
            .with_context(|| format!("--calib {}", path.display()))?;
        calibration = Some(cal.identity(path));
    }
    let built = pgrf_nn::data::build::sources(&s)?;
    for w in &built.warnings {
        eprintln!("pgrf: warning: {w}");
    }
    let (train_src, val_src, data) = (built.train, built.val, s.data.clone());
    let val_pairs = s.val_pairs;
    let seed = s.seed;
    let mix = Arc::new(mix);
    let val = if val_pairs > 0 {
        Some(ValSet::build(&val_src, &mix, val_patch, val_pairs, seed)?)
    } else {
        None
    };
    let settings = TrainSettings {
        arch: arch.clone(),
        steps,
        batch,
        patch,
        seed,
        lr: s.lr,
        schedule,
        clip_grad: s.clip_grad,
        augment: !s.no_augment,
        workers: s.workers,
        val_every: s.val_every,
        val_t2: s.val_t2,
        time_max: s.time_max,
        checkpoint_every: s.checkpoint_every,
        out: out.clone(),
        checkpoint: checkpoint_path,
        log: Some(log_path),
        log_every: s.log_every,
        resume: a.resume,
        init: s.init.clone(),
        noise: NoiseSource {
            profile: Some(profile_name.clone()),
            calibration,
            model,
            iso: s.iso,
            iso_range: iso_range.map(|(a, b)| [a, b]),
            ratio: [lo, hi],
            calibrated_dark_level: s.calibrated_dark_level,
        },
        data: data.clone(),
        device: device.to_string(),
        config: Some(s.clone()),
    };
    if a.resume && !settings.checkpoint.exists() {
        bail!(
            "--resume: no checkpoint at {}",
            settings.checkpoint.display()
        );
    }
    if !a.quiet {
        eprintln!(
            "training {} on {} ({}x{} crops, batch {batch}), noise {} from {}{}{}, {} steps, lr {:e} ({:?}){}, {} on {}",
            arch.describe(),
            train_src.describe(),
            patch,
            patch,
            settings.noise.model,
            mix.describe(),
            settings.noise.calibration.as_ref().map(|c| format!(" + calibration {c}")).unwrap_or_default(),
            if settings.noise.calibrated_dark_level { " (dark level calibrated)" } else { "" },
            steps,
            settings.lr,
            schedule,
            if s.time_max < 1.0 { format!(", times t ~ U(0, {})", s.time_max) } else { String::new() },
            device,
            pgrf_nn::backend::describe(device),
        );
    }

    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        let first: std::sync::OnceLock<std::time::Instant> = std::sync::OnceLock::new();
        // A second Ctrl-C kills at once (the first asks for a clean stop),
        // but only a second request: one that comes a second or more after
        // the first. `timeout -s INT` and other supervisors signal both the
        // process and its process group, so one request can arrive twice
        // within microseconds, and it must still save.
        let _ = ctrlc::set_handler(move || {
            let t0 = *first.get_or_init(std::time::Instant::now);
            if stop.swap(true, Ordering::SeqCst) && t0.elapsed().as_secs_f64() >= 1.0 {
                std::process::exit(130);
            }
        });
    }
    let progress = crate::progress::Bar::new("train", steps, "steps", a.quiet);
    let outcome = pgrf_nn::backend::train(
        device,
        &settings,
        Arc::new(train_src),
        mix,
        val.as_ref(),
        &progress,
        &stop,
    )?;
    report(a, &settings, &outcome)?;
    if outcome.interrupted {
        eprintln!(
            "interrupted at step {}: checkpoint {} and weights {} written; continue with --resume",
            outcome.end_step,
            settings.checkpoint.display(),
            out.display()
        );
        std::process::exit(130);
    }
    Ok(())
}

fn report(a: &TrainArgs, s: &TrainSettings, o: &Outcome) -> Result<()> {
    let val = o
        .val_psnr
        .map(|p| format!(", validation PSNR {p:.2} dB"))
        .unwrap_or_default();
    let input = o
        .val_input_psnr
        .map(|p| format!(" (noisy input {p:.2} dB)"))
        .unwrap_or_default();
    if !a.quiet {
        eprintln!(
            "steps {}..{}: final loss {:.5}{val}{input}, {:.2} images/s, {:.1} s; wrote {}",
            o.start_step,
            o.end_step,
            o.final_loss,
            o.images_per_s,
            o.seconds,
            s.out.display()
        );
    }
    if a.json {
        println!(
            "{}",
            serde_json::json!({
                "method": s.arch.method(),
                "steps": o.end_step,
                "steps_this_run": o.end_step - o.start_step,
                "final_loss": o.final_loss,
                "val_psnr": o.val_psnr,
                "val_input_psnr": o.val_input_psnr,
                "images_per_s": o.images_per_s,
                "seconds": o.seconds,
                "interrupted": o.interrupted,
                "output": s.out,
                "checkpoint": s.checkpoint,
            })
        );
    }
    Ok(())
}
