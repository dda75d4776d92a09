//! `pgrf make-dataset`: a miniature benchmark folder in the exact ELD or SID
//! layout (`pgrf_eval::dataset::miniature`), so that `pgrf eval` can be
//! checked end to end without the real datasets.

use anyhow::{bail, Result};
use clap::Args;
use pgrf_eval::dataset::miniature::{self, Layout, Miniature};
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
#[command(
    after_help = "ELD: every scene gets all 16 frames with the ISO and exposure of ELD's \
frame table (references 1, 6, 11, 16: the clean scene at ISO 100, 4 s; the others synthesised \
with the sony-a7s2 profile at their ISO, exposure and ratio). SID: scenes 10001.. get one long \
exposure (10 s, clean) and short exposures of 0.1 s, 0.04 s and 0.033 s (x100, x250, x300) at \
ISO 800, listed in Sony_test_list.txt.\n\nThen: pgrf eval --protocol eld --root DIR --scenes 1-N --model M"
)]
pub struct MakeDatasetArgs {
    /// Which benchmark's folder layout to write: eld (DIR/SonyA7S2/scene-K/IMG_0001.dng ..
    /// IMG_0016.dng, ELD's frame table) or sid (DIR/Sony/short, DIR/Sony/long and
    /// DIR/Sony_test_list.txt, SID's naming).
    #[arg(long)]
    pub layout: Layout,
    /// Output folder (created; must not hold files already).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Number of scenes (ELD's benchmark has 10).
    #[arg(long, default_value_t = 10)]
    pub scenes: u32,
    /// Frame size in pixels, WxH (even).
    #[arg(long, default_value = "256x256")]
    pub size: String,
    /// Seed of the scenes and the noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// `--size WxH` of a rendered frame: even sides of at least `min` pixels.
pub fn parse_size(s: &str, min: usize) -> Result<(usize, usize)> {
    let parsed = s.split_once(['x', 'X']).and_then(|(w, h)| {
        Some((
            w.trim().parse::<usize>().ok()?,
            h.trim().parse::<usize>().ok()?,
        ))
    });
    match parsed {
        Some((w, h)) if w >= min && h >= min && w.is_multiple_of(2) && h.is_multiple_of(2) => {
            check_frame_memory(&format!("--size {w}x{h}"), w, h, 40.0)?;
            Ok((w, h))
        }
        _ => bail!("--size {s}: expected WxH, even and at least {min}x{min}, e.g. 256x256"),
    }
}

/// Refuse a `w` x `h` frame the machine's memory cannot hold, before work:
/// `bytes_per_pixel` is the command's peak per mosaic pixel, rounded up
/// from a measurement (peak RSS of a 2048 x 2048 run on the 2-core VM:
/// make-dataset 27 B/px, simulate-sensor 98 B/px with 2 or 8 frames).
pub fn check_frame_memory(what: &str, w: usize, h: usize, bytes_per_pixel: f64) -> Result<()> {
    pgrf_core::mem::check_fits(what, w as f64 * h as f64 * bytes_per_pixel)
        .map_err(|e| anyhow::anyhow!("{e}; give a smaller size"))
}

/// The clean long exposure of scene `k`: a dead-leaves scene, dimmed so a
/// dark capture stays in range, with A7S2 metadata.
pub fn run(a: &MakeDatasetArgs) -> Result<()> {
    let (width, height) = parse_size(&a.size, 32)?;
    let m = Miniature {
        layout: a.layout,
        scenes: a.scenes,
        width,
        height,
        seed: a.seed,
    };
    let w = miniature::write(&a.output, &m)?;
    let root = a.output.display();
    match a.layout {
        Layout::Eld => {
            eprintln!(
                "wrote {} DNGs in the ELD layout under {} (scenes 1-{})",
                w.files,
                w.frames.display(),
                a.scenes
            );
            eprintln!(
                "evaluate: pgrf eval --protocol eld --root {root} --scenes 1-{} --model MODEL",
                a.scenes
            );
        }
        Layout::Sid => {
            eprintln!(
                "wrote {} DNGs in the SID layout under {} and {}",
                w.files,
                w.frames.display(),
                w.list.as_deref().unwrap_or(Path::new("")).display()
            );
            eprintln!("evaluate: pgrf eval --protocol sid --root {root} --model MODEL");
        }
    }
    Ok(())
}
