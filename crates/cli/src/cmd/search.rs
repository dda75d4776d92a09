//! `pgrf search`: the paper's sampling search (Algorithm 2). Makes
//! validation pairs like the model's training pairs, runs
//! `pgrf_nn::flow::search::run` (the two-stage sampler scored at
//! t = s, 2s, .., 1), prints the table or JSON, writes a plot of PSNR
//! against t and the best t into the weight file (`store_t2`, atomically).

use crate::progress::Bar;
use anyhow::{bail, Context, Result};
use clap::Args;
use pgrf_calib::Calibration;
use pgrf_eval::Protocol;
use pgrf_nn::backend::DeviceKind;
use pgrf_nn::data::build::validation_source;
use pgrf_nn::data::source::Source;
use pgrf_nn::data::validation::ValSet;
use pgrf_nn::flow::search::{self, SearchOptions};
use pgrf_nn::weights::{self, Architecture};
use pgrf_noise::mix::PairMix;
use pgrf_noise::pair::RatioSpec;
use pgrf_noise::ModelKind;
use pgrf_report::{write_search_plot, SearchCurve};
use serde::Serialize;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct SearchArgs {
    /// Flow model weight file (from `pgrf train flow`); its t2 is rewritten.
    #[arg(long, short = 'm')]
    pub model: PathBuf,
    /// Folder of clean RAW files, or of photos (unprocessed into the camera's
    /// RAW space as the model's training run did it), to make validation pairs from.
    #[arg(long, conflicts_with = "procedural")]
    pub val: Option<PathBuf>,
    /// Or: this many procedural scenes as validation pairs.
    #[arg(long)]
    pub procedural: Option<usize>,
    /// Number of validation pairs drawn from --val (crops of its files).
    #[arg(long, default_value_t = 8)]
    pub pairs: usize,
    /// Grid step s: t in {s, 2s, .., ns <= 1}.
    #[arg(long, default_value_t = 0.1)]
    pub step: f64,
    /// Side of the validation crops in packed pixels.
    #[arg(long, default_value_t = 256)]
    pub patch: usize,
    /// Exposure ratio of the pairs (default: drawn from the file's training range).
    #[arg(long)]
    pub ratio: Option<f32>,
    /// ISO of the synthetic noise (default: the file's, else ELD-sampled parameters).
    #[arg(long)]
    pub iso: Option<u32>,
    /// Calibration file the model was trained with (per-pixel noise maps).
    #[arg(long)]
    pub calib: Option<PathBuf>,
    /// Seed of the validation pairs and their start noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// PNG plot of PSNR against t (default: next to the model, `.search.png`).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Also measure what averaging up to K samples (different start noise)
    /// at the best t buys, reported for K = 1, 2, 4, .., K.
    #[arg(long, default_value_t = 1)]
    pub samples: usize,
    /// Measure and print, but leave the weight file as it is.
    #[arg(long)]
    pub dry_run: bool,
    /// cpu, or cuda (needs a build with `--features cuda`).
    #[arg(long, default_value = "cpu")]
    pub device: DeviceKind,
    /// One JSON line on stdout instead of the table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct Summary {
    model: String,
    pairs: usize,
    patch: usize,
    t: Vec<f64>,
    psnr: Vec<f64>,
    ssim: Vec<f64>,
    one_step: [f64; 2],
    input: [f64; 2],
    best_t2: f64,
    /// (K, PSNR, SSIM) of the mean of K samples at the best t.
    averaged: Vec<(usize, f64, f64)>,
    written: bool,
    plot: String,
    protocol: String,
}

pub fn run(a: &SearchArgs) -> Result<()> {
    let opts = SearchOptions {
        step: a.step,
        samples: a.samples,
        seed: a.seed,
        device: a.device,
        protocol: Protocol::eld(false),
    };
    // Bad --step or --samples are refused before any costly work.
    opts.times()?;
    let meta =
        weights::read_meta(&a.model).with_context(|| format!("--model {}", a.model.display()))?;
    if !matches!(meta.arch, Architecture::Sr3(_)) {
        bail!(
            "--model {}: holds an {}; the sampling search is for PGRF flow models",
            a.model.display(),
            meta.arch.describe()
        );
    }
    if a.patch < 16 {
        bail!("--patch must be at least 16 packed pixels, got {}", a.patch);
    }
    let plot = a
        .plot
        .clone()
        .unwrap_or_else(|| a.model.with_extension("search.png"));
    crate::output::require_parent_dir(&plot).context("--plot")?;
    a.device.check_available().map_err(anyhow::Error::msg)?;

    // Pairs made as the model's training pairs were (its record's noise
    // source: profile or mix, ISO or ISO range, ratios); --iso and --ratio
    // override.
    let noise = &meta.noise;
    let profile_name = noise.profile.clone().unwrap_or_else(|| "sony-a7s2".into());
    let model: ModelKind = noise.model;
    let ratio = match a.ratio {
        Some(r) if r.is_finite() && r > 0.0 => RatioSpec::Fixed(r),
        Some(r) => bail!("--ratio must be a positive number, got {r}"),
        None => RatioSpec::Uniform {
            lo: noise.ratio[0],
            hi: noise.ratio[1],
        },
    };
    let (iso, iso_range) = match a.iso {
        Some(v) => (Some(v), None),
        None => (noise.iso, noise.iso_range.map(|[lo, hi]| (lo, hi))),
    };
    let mut mix = PairMix::build(&profile_name, model, iso, iso_range, ratio)
        .with_context(|| format!("--model {}: its noise record", a.model.display()))?;
    mix.set_calibrated_dark_level(noise.calibrated_dark_level);
    if let Some(p) = &a.calib {
        let described = mix.describe();
        let Some(spec) = mix.single_mut() else {
            bail!(
                "--calib {}: the model was trained on a mix of profiles ({described}); a calibration describes one sensor",
                p.display(),
            );
        };
        let cal = Calibration::load(p)?;
        cal.apply_to(spec)
            .with_context(|| format!("--calib {}", p.display()))?;
    }
    let (source, count, what) = match (&a.val, a.procedural) {
        (Some(dir), _) => {
            // Photos are unprocessed as the model's training run did it.
            let config = (meta.training.as_ref())
                .and_then(|t| t.config.clone())
                .unwrap_or_default();
            let (src, skipped) = validation_source(&config, "--val", dir, a.patch)?;
            if !a.json {
                for w in skipped {
                    eprintln!("note: --val: {w}");
                }
            }
            let what = format!("{} crops of {}", a.pairs, src.describe());
            (src, a.pairs, what)
        }
        (None, Some(n)) => (Source::Procedural, n, format!("{n} procedural scenes")),
        (None, None) => {
            bail!("give validation data: --val DIR (clean RAW files or photos) or --procedural N")
        }
    };
    if count == 0 {
        bail!("no validation pairs: --pairs/--procedural must be at least 1");
    }
    let need = pgrf_nn::infer::memory::tile_bytes(&meta.arch, a.patch, a.patch)
        + (count * 3 * 4 * a.patch * a.patch * 4) as f64;
    pgrf_core::mem::check_fits(&format!("--patch {} with {count} pairs", a.patch), need)
        .map_err(|e| anyhow::anyhow!("{e}; give a smaller --patch or fewer pairs"))?;
    let val = ValSet::build(&source, &mix, a.patch, count, a.seed)?;

    let bar = Bar::new("search", 0, "network evaluations", a.json);
    let out = search::run(&a.model, &val, &opts, &bar)?;
    let protocol = &opts.protocol;
    let (best, best_t) = (out.best, out.best_t2);
    let times: Vec<f64> = out.curve.iter().map(|c| c.0).collect();
    let psnr: Vec<f64> = out.curve.iter().map(|c| c.1).collect();
    let (one, input) = ([out.one_step.0, out.one_step.1], [out.input.0, out.input.1]);
    let title = format!(
        "Sampling search: {}",
        a.model
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    );
    write_search_plot(
        &plot,
        &SearchCurve {
            title: &title,
            t: &times,
            psnr: &psnr,
            one_step: Some(one[0]),
            input: Some(input[0]),
            best_t,
        },
    )
    .map_err(anyhow::Error::msg)?;
    if !a.dry_run {
        search::store_t2(&a.model, best_t)?;
    }
    let header = format!(
        "{} channels 4 (packed R,G1,B,G2), {}",
        what,
        protocol.describe()
    );
    if a.json {
        let s = Summary {
            model: a.model.display().to_string(),
            pairs: count,
            patch: a.patch,
            t: times.clone(),
            psnr,
            ssim: out.curve.iter().map(|c| c.2).collect(),
            one_step: one,
            input,
            best_t2: best_t,
            averaged: out.averaging.clone(),
            written: !a.dry_run,
            plot: plot.display().to_string(),
            protocol: header,
        };
        println!("{}", serde_json::to_string(&s)?);
        return Ok(());
    }
    println!(
        "sampling search: {} ({}), {count} pairs of {p}x{p} packed, ratio {}, seed {}",
        a.model.display(),
        meta.arch.describe(),
        match ratio {
            RatioSpec::Fixed(r) => format!("{r}"),
            RatioSpec::Uniform { lo, hi } => format!("U({lo}, {hi})"),
        },
        a.seed,
        p = a.patch
    );
    let gains = match (iso, iso_range) {
        (Some(v), _) => format!(" at ISO {v}"),
        (None, Some((lo, hi))) => format!(", ISO {lo}..{hi}"),
        (None, None) => String::new(),
    };
    println!(
        "pairs: {what}; noise: {} {}{gains}",
        mix.describe(),
        noise.model
    );
    println!("protocol: {}", protocol.describe());
    println!("{:>14}  {:>9}  {:>7}", "t", "PSNR (dB)", "SSIM");
    println!(
        "{:>14}  {:>9.3}  {:>7.4}",
        "noisy input", input[0], input[1]
    );
    println!("{:>14}  {:>9.3}  {:>7.4}", "one step", one[0], one[1]);
    for (k, (t, p, q)) in out.curve.iter().enumerate() {
        println!(
            "{:>14.3}  {:>9.3}  {:>7.4}{}",
            t,
            p,
            q,
            if k == best { "  <- best" } else { "" }
        );
    }
    if a.samples > 1 {
        println!("mean of K samples at t2 = {best_t:.3}:");
        for (k, p, q) in &out.averaging {
            println!("{:>14}  {:>9.3}  {:>7.4}", format!("K = {k}"), p, q);
        }
    }
    println!(
        "t2 = {best_t:.3}{} ; plot {}",
        if a.dry_run {
            " (dry run: weight file unchanged)".to_string()
        } else {
            format!(" written to {}", a.model.display())
        },
        plot.display()
    );
    Ok(())
}
