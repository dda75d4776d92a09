//! `pgrf preview`: an sRGB PNG of a RAW file.

use crate::input::InputArgs;
use anyhow::{bail, Result};
use clap::Args;
use pgrf_raw::{render_preview, Demosaic, PreviewOptions};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct PreviewArgs {
    /// RAW file or headerless dump.
    pub file: PathBuf,
    /// Output PNG.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Linear exposure gain before clipping (e.g. 100 for a frame shot at 1/100 of normal exposure).
    #[arg(long, default_value_t = 1.0)]
    pub gain: f32,
    /// Demosaicing: malvar (gradient-corrected, default) or bilinear.
    #[arg(long, default_value = "malvar")]
    pub demosaic: Demosaic,
    /// Half-size preview, one pixel per 2x2 Bayer cell (fast, no interpolation).
    #[arg(long)]
    pub half: bool,
    /// PNG bits per channel: 8 or 16.
    #[arg(long, default_value_t = 8)]
    pub png_bits: u8,
    /// Ignore the file's as-shot white balance.
    #[arg(long)]
    pub no_wb: bool,
    /// Keep sensor orientation (do not apply the file's EXIF rotation).
    #[arg(long)]
    pub keep_orientation: bool,
    #[command(flatten)]
    pub input: InputArgs,
}

pub fn run(a: &PreviewArgs) -> Result<()> {
    if a.png_bits != 8 && a.png_bits != 16 {
        bail!("--png-bits must be 8 or 16, got {}", a.png_bits);
    }
    let frame = a.input.open(&a.file)?;
    let per_pixel = if a.half {
        pgrf_raw::memory::PREVIEW_HALF
    } else {
        pgrf_raw::memory::PREVIEW_FULL
    };
    pgrf_raw::memory::check_frame(&a.file, "previewing", frame.width, frame.height, per_pixel)?;
    let p = render_preview(
        &frame,
        &PreviewOptions {
            gain: a.gain,
            demosaic: a.demosaic,
            half: a.half,
            no_wb: a.no_wb,
            keep_orientation: a.keep_orientation,
        },
    )?;
    for w in &p.warnings {
        eprintln!("pgrf: warning: {}: {w}", a.file.display());
    }
    p.write_png(&a.output, a.png_bits)?;
    eprintln!(
        "wrote {} ({} x {}, {}-bit sRGB)",
        a.output.display(),
        p.width,
        p.height,
        a.png_bits
    );
    Ok(())
}
