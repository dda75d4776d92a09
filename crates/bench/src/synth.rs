//! `pgrf-bench synth`: the PGRF composite at full size, and the memory
//! bandwidth floor it is judged against.
//!
//! The frame is the A7S2's 4256 x 2848 mosaic packed to 4 x 1424 x 2128, a
//! smooth clean scene spanning the normalised range, ratio 100, ISO 1600; the per-pixel
//! maps are drawn once from fixed seeds (log-normal read sigma, Gaussian bias
//! and N_FP, uniform dark rate) so every component does real per-pixel work.
//! bench/pgrf_noise_numpy.py builds the same inputs and runs the same model.

use anyhow::Result;
use clap::Args;
use pgrf_core::seed::{open01, seeded_map};
use pgrf_core::stats::median;
use pgrf_noise::{CameraProfile, Capture, Components, Map, NoiseModel, PixelMaps};
use pgrf_raw::ndarray::Array3;
use rand::Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;
use serde::Serialize;
use std::sync::Arc;
use std::time::Instant;

/// Packed height of the benchmark frame (the A7S2's 2848 mosaic rows).
pub const PH: usize = 1424;
/// Packed width of the benchmark frame (the A7S2's 4256 mosaic columns).
pub const PW: usize = 2128;

/// Flags of `pgrf-bench synth`.
#[derive(Args, Debug)]
pub struct SynthArgs {
    /// Timed frames (after one warm-up).
    #[arg(long, default_value_t = 10)]
    pub frames: usize,
    /// Print one JSON line instead of text.
    #[arg(long)]
    pub json: bool,
}

/// The JSON line bench/synth.sh reads.
#[derive(Serialize)]
struct SynthResult {
    shape: [usize; 3],
    frames: usize,
    ms_median: f64,
    ms_min: f64,
    megapixels_per_s: f64,
    bytes_per_frame: f64,
    bandwidth_gb_s: f64,
    floor_ms: f64,
    ratio_to_floor: f64,
    threads: usize,
}

/// The benchmark's model and clean frame.
pub fn setup() -> Result<(NoiseModel, Array3<f32>)> {
    // The same smooth content as bench/pgrf_noise_numpy.py: the whole
    // normalised range, so both the inversion and the PTRS branch of the
    // Poisson sampler carry real load.
    let scale = [0.6f32, 1.0, 0.7, 1.0];
    let clean = Array3::from_shape_fn((4, PH, PW), |(p, i, j)| {
        (0.5 + 0.45 * (j as f32 / 97.0).sin() * (i as f32 / 61.0).cos()) * scale[p]
    });
    let profile = CameraProfile::built_in("sony-a7s2").expect("built-in");
    let params = profile.params_at_iso(1600)?;
    let sigma = params.sigma_gauss as f32;
    let maps = PixelMaps {
        bias: Map::Pixel(Arc::new(seeded_map(1, 0, PH, PW, |r| {
            r.sample::<f32, _>(StandardNormal)
        }))),
        sigma_read: Map::Pixel(Arc::new(seeded_map(2, 0, PH, PW, move |r| {
            sigma * (0.15 * r.sample::<f32, _>(StandardNormal)).exp()
        }))),
        dark_rate: Map::Pixel(Arc::new(seeded_map(3, 0, PH, PW, |r| {
            2.0 * open01(r) as f32
        }))),
        n_fp: Map::Pixel(Arc::new(seeded_map(4, 0, PH, PW, |r| {
            0.05 * r.sample::<f32, _>(StandardNormal)
        }))),
        dark_law: pgrf_noise::DarkLaw::Sqrt,
    };
    let model = NoiseModel::pgrf(&profile, &params, Some(maps), Components::ALL, false);
    Ok((model, clean))
}

/// Sustained copy bandwidth with all threads (read + write bytes per second):
/// the speed limit of any pass that streams arrays through memory.
fn bandwidth_gb_s() -> f64 {
    let n = 64 << 20; // 64 Mi f32 = 256 MiB per buffer
    let src = vec![1.0f32; n];
    let mut dst = vec![0.0f32; n];
    let mut best = f64::MAX;
    for _ in 0..5 {
        let t = Instant::now();
        dst.par_chunks_mut(1 << 16)
            .zip(src.par_chunks(1 << 16))
            .for_each(|(d, s)| d.copy_from_slice(s));
        best = best.min(t.elapsed().as_secs_f64());
        std::hint::black_box(&dst);
    }
    (2 * n * 4) as f64 / best / 1e9
}

/// Time `frames` noisy frames (one seed each) after one warm-up, then
/// measure the bandwidth floor.
pub fn run(a: &SynthArgs) -> Result<()> {
    let (frames, json) = (a.frames, a.json);
    anyhow::ensure!(frames > 0, "--frames must be at least 1");
    let (model, clean) = setup()?;
    let capture = |seed| Capture {
        ratio: 100.0,
        exposure_s: 0.1,
        plane_rows: [0, 0, 1, 1],
        seed,
    };
    std::hint::black_box(model.sample(clean.view(), &capture(0))?);
    let mut times = Vec::new();
    for f in 0..frames {
        let t = Instant::now();
        let out = model.sample(clean.view(), &capture(f as u64 + 1))?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
        std::hint::black_box(out);
    }
    let min = times.iter().copied().fold(f64::MAX, f64::min);
    let ms = median(&mut times);
    let bw = bandwidth_gb_s();
    // Per sample: clean in, four f32 maps in, result out.
    let bytes = (4 * PH * PW * (4 + 4 * 4 + 4)) as f64;
    let floor_ms = bytes / (bw * 1e9) * 1e3;
    let r = SynthResult {
        shape: [4, PH, PW],
        frames,
        ms_median: ms,
        ms_min: min,
        megapixels_per_s: (4 * PH * PW) as f64 / 1e6 / (ms / 1e3),
        bytes_per_frame: bytes,
        bandwidth_gb_s: bw,
        floor_ms,
        ratio_to_floor: ms / floor_ms,
        threads: rayon::current_num_threads(),
    };
    if json {
        println!("{}", serde_json::to_string(&r)?);
    } else {
        println!(
            "PGRF model, 4x{PH}x{PW} (12.1 MP), all components, per-pixel maps: {:.1} ms/frame median ({:.1} min), {:.1} MP/s, {} threads",
            r.ms_median, r.ms_min, r.megapixels_per_s, r.threads
        );
        println!(
            "memory bandwidth {:.1} GB/s (parallel copy); {:.0} MB touched per frame -> floor {:.1} ms; {:.1}x the floor",
            r.bandwidth_gb_s,
            bytes / 1e6,
            r.floor_ms,
            r.ratio_to_floor
        );
    }
    Ok(())
}
