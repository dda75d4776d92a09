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
    /// Also measure seams: the error's step across the borders every N packed pixels (the tile or
    /// window grid a network ran on, e.g. 128 for the built-in PGRF's windows) over the median step
    /// between neighbouring columns (rows); near 1 where there is no seam.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(2..))]
    pub seam_period: Option<u32>,
    /// With --seam-period: where the grid starts, this many packed pixels
    /// before the frame. `pgrf enhance` mirrors the frame by 4 pixels on every
    /// side before tiling it, so its tile and window borders sit at k N - 4;
    /// 0 for a grid that starts at the frame's corner.
    #[arg(long, value_name = "PIXELS", default_value_t = pgrf_nn::infer::image::EDGE_MARGIN as u32, requires = "seam_period")]
    pub seam_offset: u32,
    /// Print one JSON line: {"psnr": .., "ssim": .., "gain": .., "speckles": {"count", "flat_pixels",
    /// "sigma"}, "seam": {"worst", "axis", "at", "median_step"} or null, "protocol": ..}.
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
    speckles: pgrf_eval::Speckles,
    /// Null without --seam-period.
    seam: Option<pgrf_eval::Seams>,
    protocol: String,
}

pub fn run(a: &MetricsArgs) -> Result<()> {
    let grid = a.seam_period.map(|p| (p as usize, a.seam_offset as usize));
    let m = pgrf_eval::compare_files(&a.output, &a.reference, a.illuminance_correct, grid)?;
    let report = Report {
        psnr: m.scores.psnr.is_finite().then_some(m.scores.psnr),
        ssim: m.scores.ssim,
        gain: m.scores.gain,
        speckles: m.speckles,
        seam: m.seams,
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
    println!("speckles {}", report.speckles);
    if let Some(s) = &report.seam {
        println!("seams    {s}");
    }
    println!("protocol {}", report.protocol);
    Ok(())
}
