//! `pgrf-bench decode`: decode + pack + normalise RAW files, the work every
//! training loader and `pgrf enhance` starts with; bench/decode.sh runs LibRaw
//! (rawpy) on the same files beside it.

use anyhow::{ensure, Result};
use clap::Args;
use pgrf_core::stats::median;
use pgrf_raw::{decode_file, pack_normalized, LevelOverrides};
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;

/// Flags of `pgrf-bench decode`.
#[derive(Args, Debug)]
pub struct DecodeArgs {
    /// RAW files to time.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Timed repetitions per file (after one warm-up).
    #[arg(long, default_value_t = 20)]
    pub iters: usize,
    /// Print JSON lines instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// One file's line (the JSON bench/decode.sh reads).
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

/// Time each file: one warm-up (page cache, thread pool, lazy decoder
/// tables), then `iters` timed decode + pack runs; one line per file.
pub fn run(a: &DecodeArgs) -> Result<()> {
    ensure!(a.iters > 0, "--iters must be at least 1");
    if !a.json {
        println!(
            "{:<40} {:>6} {:>10} {:>10} {:>10} {:>10}",
            "file", "MP", "decode", "pack", "total", "min"
        );
    }
    let o = LevelOverrides::default();
    for f in &a.files {
        let frame = decode_file(f, &o)?;
        std::hint::black_box(pack_normalized(&frame, true)?);
        let (mut dec, mut pack, mut tot) = (Vec::new(), Vec::new(), Vec::new());
        for _ in 0..a.iters {
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
        let min = tot.iter().copied().fold(f64::MAX, f64::min);
        let r = DecodeResult {
            file: f.display().to_string(),
            megapixels: (frame.width * frame.height) as f64 / 1e6,
            iters: a.iters,
            decode_ms_median: median(&mut dec),
            pack_ms_median: median(&mut pack),
            total_ms_median: median(&mut tot),
            total_ms_min: min,
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
        };
        if a.json {
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
