//! `pgrf metrics`: raw-domain PSNR and SSIM of a result against its
//! reference, under the ELD protocol the published tables use.

use anyhow::Result;
use clap::Args;
use serde::Serialize;
use std::path::PathBuf;

#[derive(Args, Debug)]
#[command(
    after_help = "Both files are normalised by their own black and white levels, packed R,G1,B,G2 and \
measured as ELD does: output clamped to [0,1], both x255 as floats, PSNR with data range 255, \
SSIM with scikit-image's defaults (7x7 uniform window), averaged over the four planes.\n\n\
Identical images have infinite PSNR: text prints `inf`, --json prints `\"psnr\": null` \
(JSON has no infinity)."
)]
pub struct MetricsArgs {
    /// The image to judge (a RAW or DNG, e.g. what `pgrf enhance` wrote).
    pub output: PathBuf,
    /// The ground truth (a RAW or DNG of the same size and CFA).
    pub reference: PathBuf,
    /// Fit ELD's single least-squares brightness gain of OUTPUT onto REFERENCE
    /// (over unsaturated reference pixels) before measuring.
    #[arg(long)]
    pub illuminance_correct: bool,
    /// Print one JSON line: {"psnr": .., "ssim": .., "gain": .., "protocol": ..}.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct Report {
    /// `None` (JSON null) when infinite.
    psnr: Option<f64>,
    ssim: f64,
    /// The illuminance gain applied; null without --illuminance-correct.
    gain: Option<f64>,
    protocol: String,
}

pub fn run(a: &MetricsArgs) -> Result<()> {
    let m = pgrf_eval::compare_files(&a.output, &a.reference, a.illuminance_correct)?;
    let report = Report {
        psnr: m.scores.psnr.is_finite().then_some(m.scores.psnr),
        ssim: m.scores.ssim,
        gain: m.scores.gain,
        protocol: m.protocol,
    };
    if a.json {
        println!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    match report.psnr {
        Some(p) => println!("PSNR     {p:.4} dB"),
        None => println!("PSNR     inf dB (identical after normalisation)"),
    }
    println!("SSIM     {:.6}", report.ssim);
    if let Some(g) = report.gain {
        println!("gain     {g:.6}");
    }
    println!("protocol {}", report.protocol);
    Ok(())
}
