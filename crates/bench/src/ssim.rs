//! `pgrf-bench ssim`: PSNR + SSIM under the ELD protocol on an A7S2-sized
//! packed pair (4 x 1424 x 2128), the cost of scoring one test image.
//!
//! The pair is deterministic and cheap to rebuild in numpy, so
//! bench/ssim_skimage.py times scikit-image on the very same values and
//! bench/ssim.sh checks that both print the same scores:
//!
//! ```text
//! reference[c, i, j] = f32(4 |(i + 2 j + 16 c) % 512 - 256| + (7 i + 3 j) % 41) / f32(1100)
//! u[k]   = (splitmix64(SEED + k) >> 40) / 2^24          k = flat C-order index
//! output = 0.9 * reference + (u - 0.5) * 0.05           (f32 operations)
//! ```
//!
//! `splitmix64` is one step of SplitMix64, `pgrf_core::seed::mix64`.

use anyhow::{ensure, Result};
use clap::Args;
use pgrf_core::seed::mix64;
use pgrf_core::stats::median;
use pgrf_eval::{evaluate, Protocol};
use pgrf_raw::ndarray::Array3;
use rayon::prelude::*;
use serde::Serialize;
use std::time::Instant;

/// The packed pair's shape: an A7S2 frame, `(planes, height, width)`.
pub const SHAPE: (usize, usize, usize) = (4, 1424, 2128);
/// Seed of the output's noise (see the module docs).
const SEED: u64 = 7;

/// Flags of `pgrf-bench ssim`.
#[derive(Args, Debug)]
pub struct SsimArgs {
    /// Timed repetitions (after one warm-up).
    #[arg(long, default_value_t = 10)]
    pub iters: usize,
    /// Print one JSON line instead of text.
    #[arg(long)]
    pub json: bool,
}

/// The benchmark pair `(output, reference)`; see the module docs.
pub fn pair() -> (Array3<f32>, Array3<f32>) {
    let (c, h, w) = SHAPE;
    let n = c * h * w;
    let reference: Vec<f32> = (0..n)
        .into_par_iter()
        .map(|k| {
            let (ch, i, j) = (k / (h * w), k / w % h, k % w);
            let tri = ((i + 2 * j + 16 * ch) % 512).abs_diff(256);
            (4 * tri + (7 * i + 3 * j) % 41) as f32 / 1100.0
        })
        .collect();
    let output: Vec<f32> = reference
        .par_iter()
        .enumerate()
        .map(|(k, &r)| {
            let u = (mix64(SEED.wrapping_add(k as u64)) >> 40) as f32 / 16_777_216.0;
            0.9 * r + (u - 0.5) * 0.05
        })
        .collect();
    (
        Array3::from_shape_vec(SHAPE, output).expect("shape"),
        Array3::from_shape_vec(SHAPE, reference).expect("shape"),
    )
}

/// The JSON line bench/ssim.sh reads.
#[derive(Serialize)]
struct SsimBench {
    shape: [usize; 3],
    iters: usize,
    /// ELD protocol with the illuminance correction: gain fit + PSNR + SSIM.
    ms_median: f64,
    ms_min: f64,
    /// Without the correction: PSNR + SSIM only.
    ms_median_uncorrected: f64,
    psnr: f64,
    ssim: f64,
    gain: f64,
    psnr_uncorrected: f64,
    ssim_uncorrected: f64,
    threads: usize,
}

/// Time the protocol with and without the illuminance correction, `iters`
/// runs each after one warm-up, and print the scores with the timings.
pub fn run(a: &SsimArgs) -> Result<()> {
    let (iters, json) = (a.iters, a.json);
    ensure!(iters > 0, "--iters must be at least 1");
    let (out, reference) = pair();
    let time = |p: &Protocol| -> Result<(Vec<f64>, pgrf_eval::Scores)> {
        // Warm-up: rayon pool, page faults of the inputs.
        let s = evaluate(out.view(), reference.view(), p)?;
        let mut ms = Vec::with_capacity(iters);
        for _ in 0..iters {
            let t = Instant::now();
            std::hint::black_box(evaluate(out.view(), reference.view(), p)?);
            ms.push(t.elapsed().as_secs_f64() * 1e3);
        }
        Ok((ms, s))
    };
    let (mut ms, corrected) = time(&Protocol::eld(true))?;
    let (mut ms_plain, plain) = time(&Protocol::eld(false))?;
    let r = SsimBench {
        shape: [SHAPE.0, SHAPE.1, SHAPE.2],
        iters,
        ms_min: ms.iter().copied().fold(f64::MAX, f64::min),
        ms_median: median(&mut ms),
        ms_median_uncorrected: median(&mut ms_plain),
        psnr: corrected.psnr,
        ssim: corrected.ssim,
        gain: corrected.gain.unwrap_or(f64::NAN),
        psnr_uncorrected: plain.psnr,
        ssim_uncorrected: plain.ssim,
        threads: rayon::current_num_threads(),
    };
    if json {
        println!("{}", serde_json::to_string(&r)?);
    } else {
        println!(
            "PSNR+SSIM on {}x{}x{} (ELD protocol, {} threads): {:.1} ms median, {:.1} ms min with illuminance correction; {:.1} ms without",
            SHAPE.0, SHAPE.1, SHAPE.2, r.threads, r.ms_median, r.ms_min, r.ms_median_uncorrected
        );
        println!(
            "scores: corrected PSNR {:.6} SSIM {:.6} (gain {:.6}); uncorrected PSNR {:.6} SSIM {:.6}",
            r.psnr, r.ssim, r.gain, r.psnr_uncorrected, r.ssim_uncorrected
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_noise_is_splitmix64_as_the_numpy_script_draws_it() {
        // SplitMix64's first output from state 0 (Vigna's reference code).
        assert_eq!(mix64(0), 0xe220_a839_7b1d_cdaf);
        // The first output value of the pair, from the module docs' formula:
        // reference[0, 0, 0] = 4 * 256 / 1100.
        let u = (mix64(SEED) >> 40) as f32 / 16_777_216.0;
        let r = (4 * 256) as f32 / 1100.0;
        let (out, reference) = pair();
        assert_eq!(reference[[0, 0, 0]], r);
        assert_eq!(out[[0, 0, 0]], 0.9 * r + (u - 0.5) * 0.05);
    }
}
