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
