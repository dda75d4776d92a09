//! `pgrf search`: the paper's sampling search. Scores the two-stage sampler
//! at t = s, 2s, .., 1 on validation pairs made like the training pairs,
//! prints the table, writes the best t into the weight file (atomically) and
//! a plot of PSNR against t.

use anyhow::{bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use pgrf_calib::Calibration;
use pgrf_eval::search_plot::{write_search_plot, SearchCurve};
use pgrf_eval::{evaluate, Protocol};
use pgrf_nn::backend::DeviceKind;
use pgrf_nn::data::source::{Folder, Source};
use pgrf_nn::data::validation::ValSet;
use pgrf_nn::search::{averaging, grid, reported_counts, search, Averaging, Candidate};
use pgrf_nn::weights::{self, Architecture};
use pgrf_noise::pair::{PairSpec, RatioSpec};
use pgrf_noise::{CameraProfile, ModelKind};
use pgrf_raw::LevelOverrides;
use serde::Serialize;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct SearchArgs {
    /// Flow model weight file (from `pgrf train flow`); its t2 is rewritten.
    #[arg(long, short = 'm')]
    pub model: PathBuf,
    /// Folder of clean RAW files to make validation pairs from.
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
    let times = grid(a.step)?;
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

    // Pairs made as the model's training pairs were (its record's noise source).
    let noise = &meta.noise;
    let profile_name = noise.profile.clone().unwrap_or_else(|| "sony-a7s2".into());
    let model: ModelKind = noise.model.parse().map_err(anyhow::Error::msg)?;
    let mut spec = PairSpec::new(CameraProfile::load(&profile_name)?, model);
    spec.iso = a.iso.or(noise.iso);
    spec.ratio = match a.ratio {
        Some(r) if r.is_finite() && r > 0.0 => RatioSpec::Fixed(r),
        Some(r) => bail!("--ratio must be a positive number, got {r}"),
        None => RatioSpec::Uniform {
            lo: noise.ratio[0],
            hi: noise.ratio[1],
        },
    };
    if let Some(p) = &a.calib {
        let cal = Calibration::load(p)?;
        cal.apply_to(&mut spec)
            .with_context(|| format!("--calib {}", p.display()))?;
    }
    let (source, count, what) = match (&a.val, a.procedural) {
        (Some(dir), _) => {
            let files = Folder::list(dir)?;
            let f = Folder::new(files, LevelOverrides::default(), 1024)?;
            f.check(a.patch)?;
            let src = Source::Folder(f);
            let what = format!("{} crops of {}", a.pairs, src.describe());
            (src, a.pairs, what)
        }
        (None, Some(n)) => (Source::Procedural, n, format!("{n} procedural scenes")),
        (None, None) => {
            bail!("give validation data: --val DIR (clean RAW files) or --procedural N")
        }
    };
    if count == 0 {
        bail!("no validation pairs: --pairs/--procedural must be at least 1");
    }
    if a.samples == 0 || a.samples > 64 {
        bail!("--samples must be from 1 to 64, got {}", a.samples);
    }
    let val = ValSet::build(&source, &spec, a.patch, count, a.seed)?;

    let protocol = Protocol::eld(false);
    let n_t = times.len();
    let mut psnr = vec![0.0f64; n_t];
    let mut ssim = vec![0.0f64; n_t];
    let mut one = [0.0f64; 2];
    let mut input = [0.0f64; 2];
    let shape = (4, a.patch, a.patch);
    for p in &val.pairs {
        let noisy = pgrf_raw::ndarray::ArrayView3::from_shape(shape, &p.noisy)?;
        let clean = pgrf_raw::ndarray::ArrayView3::from_shape(shape, &p.clean)?;
        let s = evaluate(noisy, clean, &protocol)?;
        input[0] += s.psnr / count as f64;
        input[1] += s.ssim / count as f64;
    }
    let extra = if a.samples > 1 { a.samples } else { 0 };
    let bar = ProgressBar::new((count * (n_t + 1 + extra)) as u64).with_style(
        ProgressStyle::with_template(
            "{spinner} search [{bar:30}] {pos}/{len} network evaluations  {per_sec}  eta {eta}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    if a.json {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let pairs = &val.pairs;
    search(
        &a.model,
        a.device,
        pairs,
        a.patch,
        &times,
        &mut |i, cand| {
            let clean = pgrf_raw::ndarray::ArrayView3::from_shape(shape, &pairs[i].clean)
                .map_err(|e| pgrf_nn::NnError::Invalid(e.to_string()))?;
            let (out, slot) = match cand {
                Candidate::OneStep(o) => (o, None),
                Candidate::TwoStage { index, out } => (out, Some(index)),
            };
            let s = evaluate(out.view(), clean, &protocol)
                .map_err(|e| pgrf_nn::NnError::Invalid(e.to_string()))?;
            let (p, q) = (s.psnr / count as f64, s.ssim / count as f64);
            match slot {
                None => {
                    one[0] += p;
                    one[1] += q;
                }
                Some(k) => {
                    psnr[k] += p;
                    ssim[k] += q;
                }
            }
            Ok(())
        },
        &mut || bar.inc(1),
    )?;
    // Best mean PSNR; ties go to the smaller t.
    let best = (0..n_t).fold(0, |b, k| if psnr[k] > psnr[b] { k } else { b });
    let best_t = times[best];
    let counts = reported_counts(a.samples);
    let mut averaged: Vec<(usize, f64, f64)> = counts.iter().map(|&k| (k, 0.0, 0.0)).collect();
    if a.samples > 1 {
        averaging(
            &a.model,
            a.device,
            pairs,
            a.patch,
            Averaging {
                t2: best_t,
                k_max: a.samples,
                seed: a.seed,
            },
            &mut |i, k, out| {
                let clean = pgrf_raw::ndarray::ArrayView3::from_shape(shape, &pairs[i].clean)
                    .map_err(|e| pgrf_nn::NnError::Invalid(e.to_string()))?;
                let s = evaluate(out.view(), clean, &protocol)
                    .map_err(|e| pgrf_nn::NnError::Invalid(e.to_string()))?;
                if let Some(slot) = averaged.iter_mut().find(|(kk, _, _)| *kk == k) {
                    slot.1 += s.psnr / count as f64;
                    slot.2 += s.ssim / count as f64;
                }
                Ok(())
            },
            &mut || bar.inc(1),
        )?;
    } else {
        averaged = vec![(1, psnr[best], ssim[best])];
    }
    bar.finish_and_clear();
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
        weights::update_meta(&a.model, |m| m.t2 = Some(best_t as f32))?;
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
            ssim,
            one_step: one,
            input,
            best_t2: best_t,
            averaged,
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
        match spec.ratio {
            RatioSpec::Fixed(r) => format!("{r}"),
            RatioSpec::Uniform { lo, hi } => format!("U({lo}, {hi})"),
        },
        a.seed,
        p = a.patch
    );
    println!("pairs: {what}; noise: {} {}", profile_name, noise.model);
    println!("protocol: {}", protocol.describe());
    println!("{:>14}  {:>9}  {:>7}", "t", "PSNR (dB)", "SSIM");
    println!(
        "{:>14}  {:>9.3}  {:>7.4}",
        "noisy input", input[0], input[1]
    );
    println!("{:>14}  {:>9.3}  {:>7.4}", "one step", one[0], one[1]);
    for k in 0..n_t {
        println!(
            "{:>14.3}  {:>9.3}  {:>7.4}{}",
            times[k],
            psnr[k],
            ssim[k],
            if k == best { "  <- best" } else { "" }
        );
    }
    if a.samples > 1 {
        println!("mean of K samples at t2 = {best_t:.3}:");
        for (k, p, q) in &averaged {
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
