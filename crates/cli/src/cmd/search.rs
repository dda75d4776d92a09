//! `pgrf search`: the paper's sampling search (Algorithm 2). Its flags
//! become a `SearchRequest`; `pgrf_nn::flow::search::run` makes validation
//! pairs like the model's training pairs, scores the two-stage sampler at
//! t = s, 2s, .., 1 and writes the best t into the weight file
//! (atomically); this prints the table or JSON and a plot of PSNR against t.

use crate::progress::Bar;
use anyhow::{Context, Result};
use clap::Args;
use pgrf_eval::Protocol;
use pgrf_nn::backend::DeviceKind;
use pgrf_nn::flow::search::{
    self, SearchOptions, SearchOutcome, SearchRequest, Searched, ValPairs,
};
use pgrf_noise::pair::RatioSpec;
use pgrf_report::{write_search_plot, SearchCurve};
use serde::Serialize;
use std::path::{Path, PathBuf};

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
    let plot = a
        .plot
        .clone()
        .unwrap_or_else(|| a.model.with_extension("search.png"));
    crate::output::require_parent_dir(&plot).context("--plot")?;
    let req = request(a);
    let bar = Bar::new("search", 0, "network evaluations", a.json);
    let warn = |w: &str| {
        if !a.json {
            eprintln!("note: --val: {w}");
        }
    };
    let found = search::run(&req, &bar, &warn)?;
    write_plot(a, &plot, &found.outcome)?;
    if a.json {
        print_json(a, &req, &found, &plot)
    } else {
        print_table(a, &req, &found, &plot);
        Ok(())
    }
}

/// The flags as a search request.
fn request(a: &SearchArgs) -> SearchRequest {
    let val = match (&a.val, a.procedural) {
        (Some(path), _) => Some(ValPairs::Files {
            path: path.clone(),
            pairs: a.pairs,
        }),
        (None, Some(n)) => Some(ValPairs::Procedural(n)),
        (None, None) => None,
    };
    SearchRequest {
        model: a.model.clone(),
        val,
        patch: a.patch,
        ratio: a.ratio,
        iso: a.iso,
        calib: a.calib.clone(),
        dry_run: a.dry_run,
        options: SearchOptions {
            step: a.step,
            samples: a.samples,
            seed: a.seed,
            device: a.device,
            protocol: Protocol::eld(false),
        },
    }
}

/// PSNR against t, the one-step sampler, the input and the best t.
fn write_plot(a: &SearchArgs, plot: &Path, out: &SearchOutcome) -> Result<()> {
    let times: Vec<f64> = out.curve.iter().map(|c| c.0).collect();
    let psnr: Vec<f64> = out.curve.iter().map(|c| c.1).collect();
    let title = format!(
        "Sampling search: {}",
        a.model
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    );
    write_search_plot(
        plot,
        &SearchCurve {
            title: &title,
            t: &times,
            psnr: &psnr,
            one_step: Some(out.one_step.0),
            input: Some(out.input.0),
            best_t: out.best_t2,
        },
    )
    .map_err(anyhow::Error::msg)
}

fn print_json(a: &SearchArgs, req: &SearchRequest, found: &Searched, plot: &Path) -> Result<()> {
    let out = &found.outcome;
    let header = format!(
        "{} channels 4 (packed R,G1,B,G2), {}",
        found.what,
        req.options.protocol.describe()
    );
    let s = Summary {
        model: a.model.display().to_string(),
        pairs: found.pairs,
        patch: a.patch,
        t: out.curve.iter().map(|c| c.0).collect(),
        psnr: out.curve.iter().map(|c| c.1).collect(),
        ssim: out.curve.iter().map(|c| c.2).collect(),
        one_step: [out.one_step.0, out.one_step.1],
        input: [out.input.0, out.input.1],
        best_t2: out.best_t2,
        averaged: out.averaging.clone(),
        written: found.written,
        plot: plot.display().to_string(),
        protocol: header,
    };
    println!("{}", serde_json::to_string(&s)?);
    Ok(())
}

fn print_table(a: &SearchArgs, req: &SearchRequest, found: &Searched, plot: &Path) {
    let out = &found.outcome;
    let (best, best_t) = (out.best, out.best_t2);
    println!(
        "sampling search: {} ({}), {} pairs of {p}x{p} packed, ratio {}, seed {}",
        a.model.display(),
        found.meta.arch.describe(),
        found.pairs,
        match found.ratio {
            RatioSpec::Fixed(r) => format!("{r}"),
            RatioSpec::Uniform { lo, hi } => format!("U({lo}, {hi})"),
        },
        a.seed,
        p = a.patch
    );
    let gains = match (found.iso, found.iso_range) {
        (Some(v), _) => format!(" at ISO {v}"),
        (None, Some((lo, hi))) => format!(", ISO {lo}..{hi}"),
        (None, None) => String::new(),
    };
    println!(
        "pairs: {}; noise: {} {}{gains}",
        found.what, found.profiles, found.meta.noise.model
    );
    println!("protocol: {}", req.options.protocol.describe());
    println!("{:>14}  {:>9}  {:>7}", "t", "PSNR (dB)", "SSIM");
    println!(
        "{:>14}  {:>9.3}  {:>7.4}",
        "noisy input", out.input.0, out.input.1
    );
    println!(
        "{:>14}  {:>9.3}  {:>7.4}",
        "one step", out.one_step.0, out.one_step.1
    );
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
}
