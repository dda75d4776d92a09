//! `pgrf bench`: timings of pgrf's hot paths, for BENCHMARKS.md. Medians over
//! repeated runs after one warm-up; bench/ holds the scripts that run the
//! peers (LibRaw via rawpy) in the same session.

use anyhow::{bail, Result};
use clap::{Args, Subcommand};
use pgrf_raw::{decode_file, pack_normalized, LevelOverrides};
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct BenchArgs {
    #[command(subcommand)]
    pub what: BenchWhat,
}

#[derive(Subcommand, Debug)]
pub enum BenchWhat {
    /// Full PGRF noise model (all components, per-pixel maps) on an A7S2-sized
    /// frame (4 x 1424 x 2128 packed), plus this machine's memory bandwidth.
    Synth {
        /// Timed frames (after one warm-up).
        #[arg(long, default_value_t = 10)]
        frames: usize,
        /// Print one JSON line instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Per-pixel statistics of a bias stack (decode + Welford accumulation),
    /// with the decode-only time and this process's peak memory.
    Stack {
        /// Folder of bias frames.
        dir: PathBuf,
        /// Print one JSON line instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Decode + pack + normalise RAW files.
    Decode {
        /// RAW files to time.
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Timed repetitions per file (after one warm-up).
        #[arg(long, default_value_t = 20)]
        iters: usize,
        /// Print JSON lines instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Forward and training-step time of the SID U-Net and the SR3 velocity
    /// field on the CPU (bench/train.sh runs PyTorch beside it).
    Train(crate::cmd::bench_train::TrainArgs),
    /// Inference on a whole frame (`pgrf enhance`'s network part: tiles,
    /// sampler, blend) with either network; bench/enhance.sh runs PyTorch beside it.
    Enhance(crate::cmd::bench_enhance::EnhanceArgs),
    /// PSNR + SSIM under the ELD protocol on a deterministic A7S2-sized pair
    /// (4 x 1424 x 2128 packed); bench/ssim.sh times scikit-image beside it.
    Ssim {
        /// Timed repetitions (after one warm-up).
        #[arg(long, default_value_t = 10)]
        iters: usize,
        /// Print one JSON line instead of text.
        #[arg(long)]
        json: bool,
    },
}

#[derive(Serialize)]
struct DecodeResult {
    file: String,
    megapixels: f64,
    iters: usize,
    decode_ms_median: f64,
    pack_ms_median: f64,
    total_ms_median: f64,
    total_ms_min: f64,
    threads: usize,
}

pub(crate) fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

pub fn run(a: &BenchArgs) -> Result<()> {
    match &a.what {
        BenchWhat::Synth { frames, json } => crate::cmd::bench_synth::run(*frames, *json),
        BenchWhat::Stack { dir, json } => bench_stack(dir, *json),
        BenchWhat::Train(t) => crate::cmd::bench_train::run(t),
        BenchWhat::Enhance(e) => crate::cmd::bench_enhance::run(e),
        BenchWhat::Ssim { iters, json } => crate::cmd::bench_ssim::run(*iters, *json),
        BenchWhat::Decode { files, iters, json } => {
            if *iters == 0 {
                bail!("--iters must be at least 1");
            }
            if !json {
                println!(
                    "{:<40} {:>6} {:>10} {:>10} {:>10} {:>10}",
                    "file", "MP", "decode", "pack", "total", "min"
                );
            }
            for f in files {
                let o = LevelOverrides::default();
                // Warm-up: page cache, rayon pool, lazy decoder tables.
                let frame = decode_file(f, &o)?;
                std::hint::black_box(pack_normalized(&frame, true)?);
                let (mut dec, mut pack, mut tot) = (Vec::new(), Vec::new(), Vec::new());
                for _ in 0..*iters {
                    let t0 = Instant::now();
                    let frame = decode_file(f, &o)?;
                    let t1 = Instant::now();
                    let p = pack_normalized(&frame, true)?;
                    let t2 = Instant::now();
                    std::hint::black_box(&p);
                    dec.push((t1 - t0).as_secs_f64() * 1e3);
                    pack.push((t2 - t1).as_secs_f64() * 1e3);
                    tot.push((t2 - t0).as_secs_f64() * 1e3);
                }
                let min = tot.iter().cloned().fold(f64::MAX, f64::min);
                let r = DecodeResult {
                    file: f.display().to_string(),
                    megapixels: (frame.width * frame.height) as f64 / 1e6,
                    iters: *iters,
                    decode_ms_median: median(&mut dec),
                    pack_ms_median: median(&mut pack),
                    total_ms_median: median(&mut tot),
                    total_ms_min: min,
                    threads: pgrf_raw_threads(),
                };
                if *json {
                    println!("{}", serde_json::to_string(&r)?);
                } else {
                    let name = f
                        .file_name()
                        .map(|n| n.to_string_lossy().into_owned())
                        .unwrap_or_default();
                    println!(
                        "{:<40} {:>6.2} {:>8.2}ms {:>8.2}ms {:>8.2}ms {:>8.2}ms",
                        name,
                        r.megapixels,
                        r.decode_ms_median,
                        r.pack_ms_median,
                        r.total_ms_median,
                        r.total_ms_min
                    );
                }
            }
            Ok(())
        }
    }
}

fn pgrf_raw_threads() -> usize {
    std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
}

/// Peak resident memory of this process so far (VmHWM), MiB.
fn peak_rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| {
                l.split_whitespace()
                    .nth(1)
                    .and_then(|v| v.parse::<f64>().ok())
            })
        })
        .map(|kb| kb / 1024.0)
        .unwrap_or(f64::NAN)
}

fn bench_stack(dir: &std::path::Path, json: bool) -> Result<()> {
    use pgrf_calib::stack::{list_files, read_stack, ReadOptions};
    use rayon::prelude::*;
    let files = list_files(dir)?;
    let t = Instant::now();
    let stack = read_stack(
        &files,
        &ReadOptions {
            kind: "bias",
            expect: None,
            single_exposure: true,
            need_exposure: false,
            tap_pixels: 0,
            progress: &|| {},
        },
    )?;
    let bias = pgrf_calib::estimate::estimate_bias(&stack, stack.key.black)?;
    let total_s = t.elapsed().as_secs_f64();
    let peak = peak_rss_mib();
    std::hint::black_box(&bias);
    // Decode alone, with the same parallelism, for the decode-bound fraction.
    let t = Instant::now();
    files.par_iter().try_for_each(|f| -> Result<()> {
        std::hint::black_box(decode_file(f, &LevelOverrides::default())?);
        Ok(())
    })?;
    let decode_s = t.elapsed().as_secs_f64();
    let r = serde_json::json!({
        "frames": files.len(),
        "megapixels": (stack.key.width * stack.key.height) as f64 / 1e6,
        "total_s": total_s,
        "decode_only_s": decode_s,
        "decode_fraction": decode_s / total_s,
        "peak_rss_mib": peak,
        "read_sigma_median": pgrf_calib::estimate::median_of(&bias.sigma_read),
        "threads": rayon::current_num_threads(),
    });
    if json {
        println!("{r}");
    } else {
        println!(
            "{} frames of {:.1} MP: {:.2} s (decode alone {:.2} s, {:.0}%), peak memory {:.0} MiB",
            files.len(),
            r["megapixels"].as_f64().unwrap_or(0.0),
            total_s,
            decode_s,
            100.0 * decode_s / total_s,
            peak
        );
    }
    Ok(())
}
