//! `pgrf-bench stack`: the bias part of `pgrf calibrate` (decode every frame,
//! per-pixel Welford statistics, bias estimates), the same files decoded
//! alone for the decode-bound fraction, and the process's peak memory;
//! bench/calib.sh runs numpy beside it.

use anyhow::Result;
use clap::Args;
use pgrf_calib::stack::{read_stack, ReadOptions};
use pgrf_raw::files::list_files;
use pgrf_raw::{decode_file, LevelOverrides};
use rayon::prelude::*;
use std::path::PathBuf;
use std::time::Instant;

/// Flags of `pgrf-bench stack`.
#[derive(Args, Debug)]
pub struct StackArgs {
    /// Folder of bias frames.
    pub dir: PathBuf,
    /// Print one JSON line instead of text.
    #[arg(long)]
    pub json: bool,
}

/// One run over the folder (no repetitions: a 64-frame stack takes tens of
/// seconds), then the decode-only pass with the same parallelism.
pub fn run(a: &StackArgs) -> Result<()> {
    let files = list_files(&a.dir)?;
    let t = Instant::now();
    let stack = read_stack(&files, &ReadOptions::bias(0, false, &pgrf_core::NoProgress))?;
    let bias = pgrf_calib::estimate::estimate_bias(&stack, stack.key.black)?;
    let total_s = t.elapsed().as_secs_f64();
    let peak = pgrf_core::mem::peak_rss_mib().unwrap_or(f64::NAN);
    std::hint::black_box(&bias);
    let t = Instant::now();
    files.par_iter().try_for_each(|f| -> Result<()> {
        std::hint::black_box(decode_file(f, &LevelOverrides::default())?);
        Ok(())
    })?;
    let decode_s = t.elapsed().as_secs_f64();
    let megapixels = (stack.key.width * stack.key.height) as f64 / 1e6;
    let r = serde_json::json!({
        "frames": files.len(),
        "megapixels": megapixels,
        "total_s": total_s,
        "decode_only_s": decode_s,
        "decode_fraction": decode_s / total_s,
        "peak_rss_mib": peak,
        "read_sigma_median": pgrf_core::stats::median_finite(&bias.sigma_read),
        "threads": rayon::current_num_threads(),
    });
    if a.json {
        println!("{r}");
    } else {
        println!(
            "{} frames of {megapixels:.1} MP: {total_s:.2} s (decode alone {decode_s:.2} s, {:.0}%), peak memory {peak:.0} MiB",
            files.len(),
            100.0 * decode_s / total_s,
        );
    }
    Ok(())
}
