//! What `pgrf search` prints about a finished search: the table of PSNR
//! and SSIM against t, or one JSON record; and the plot of PSNR against t
//! it draws before the chosen t2 is stored.

use super::{SearchOutcome, SearchRequest, Searched};
use pgrf_nn::{NnError, Result};
use pgrf_noise::pair::RatioSpec;
use pgrf_report::{write_search_plot, SearchCurve};
use serde::Serialize;
use std::fmt::Write;

/// `pgrf search --json`'s record.
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
    /// The kept t2 is the smallest t within this many dB of the best PSNR.
    tolerance_db: f64,
    /// (K, PSNR, SSIM) of the mean of K samples at the best t.
    averaged: Vec<(usize, f64, f64)>,
    written: bool,
    plot: String,
    protocol: String,
}

/// PSNR against t, the one-step sampler, the input and the best t, drawn
/// to the request's plot.
pub(super) fn write_plot(req: &SearchRequest, out: &SearchOutcome) -> Result<()> {
    let times: Vec<f64> = out.curve.iter().map(|c| c.0).collect();
    let psnr: Vec<f64> = out.curve.iter().map(|c| c.1).collect();
    let title = format!(
        "Sampling search: {}",
        (req.model.file_name())
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    );
    write_search_plot(
        &req.plot,
        &SearchCurve {
            title: &title,
            t: &times,
            psnr: &psnr,
            one_step: Some(out.one_step.0),
            input: Some(out.input.0),
            best_t: out.best_t2,
        },
    )
    .map_err(|e| NnError::Caller(Box::new(e)))
}

impl Searched {
    /// The search as one JSON line.
    pub fn json(&self, req: &SearchRequest) -> String {
        let out = &self.outcome;
        let header = format!(
            "{} channels 4 (packed R,G1,B,G2), {}",
            self.what,
            req.options.protocol.describe()
        );
        let s = Summary {
            model: req.model.display().to_string(),
            pairs: self.pairs,
            patch: req.patch,
            t: out.curve.iter().map(|c| c.0).collect(),
            psnr: out.curve.iter().map(|c| c.1).collect(),
            ssim: out.curve.iter().map(|c| c.2).collect(),
            one_step: [out.one_step.0, out.one_step.1],
            input: [out.input.0, out.input.1],
            best_t2: out.best_t2,
            tolerance_db: req.options.tolerance_db,
            averaged: out.averaging.clone(),
            written: self.written,
            plot: req.plot.display().to_string(),
            protocol: header,
        };
        serde_json::to_string(&s).expect("a record of numbers and strings serialises")
    }

    /// The search as the table `pgrf search` prints: what was measured, the
    /// input, the one-step sampler, every t (the best marked), the averaging
    /// study, and where t2 went.
    pub fn table(&self, req: &SearchRequest) -> String {
        let out = &self.outcome;
        let (best, best_t) = (out.best, out.best_t2);
        let mut s = String::new();
        let _ = writeln!(
            s,
            "sampling search: {} ({}), {} pairs of {p}x{p} packed, ratio {}, seed {}",
            req.model.display(),
            self.meta.arch.describe(),
            self.pairs,
            match self.ratio {
                RatioSpec::Fixed(r) => format!("{r}"),
                RatioSpec::Uniform { lo, hi } => format!("U({lo}, {hi})"),
                RatioSpec::LogUniform { lo, hi } => format!("logU({lo}, {hi})"),
            },
            req.options.seed,
            p = req.patch
        );
        let gains = match (self.iso, self.iso_range) {
            (Some(v), _) => format!(" at ISO {v}"),
            (None, Some((lo, hi))) => format!(", ISO {lo}..{hi}"),
            (None, None) => String::new(),
        };
        let _ = writeln!(
            s,
            "pairs: {}; noise: {} {}{gains}",
            self.what, self.profiles, self.meta.noise.model
        );
        let _ = writeln!(s, "protocol: {}", req.options.protocol.describe());
        let _ = writeln!(s, "{:>14}  {:>9}  {:>7}", "t", "PSNR (dB)", "SSIM");
        let row = |s: &mut String, name: &str, (p, q): (f64, f64)| {
            let _ = writeln!(s, "{name:>14}  {p:>9.3}  {q:>7.4}");
        };
        row(&mut s, "noisy input", out.input);
        row(&mut s, "one step", out.one_step);
        for (k, (t, p, q)) in out.curve.iter().enumerate() {
            let mark = if k == best { "  <- kept" } else { "" };
            let _ = writeln!(s, "{t:>14.3}  {p:>9.3}  {q:>7.4}{mark}");
        }
        if req.options.samples > 1 {
            let _ = writeln!(s, "mean of K samples at t2 = {best_t:.3}:");
            for (k, p, q) in &out.averaging {
                row(&mut s, &format!("K = {k}"), (*p, *q));
            }
        }
        let _ = writeln!(
            s,
            "kept: the smallest t within {} dB of the best PSNR",
            req.options.tolerance_db
        );
        let _ = writeln!(
            s,
            "t2 = {best_t:.3}{} ; plot {}",
            if req.dry_run {
                " (dry run: weight file unchanged)".to_string()
            } else {
                format!(" written to {}", req.model.display())
            },
            req.plot.display()
        );
        s
    }
}
