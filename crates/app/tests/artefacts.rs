//! Issue 51, lever 6: the built-in models restore a small seeded frame
//! without a grid at the flow's internal windows and without ring-shaped
//! speckles, measured with `pgrf_eval`'s artefact metrics.
//!
//! The frame is smooth (gentle ramps and a slow wave, no structure on any
//! grid, so that a step of the error at a window border is the network's
//! and not the picture's), 384 x 512 packed pixels: 3 x 4 of the PGRF's
//! 128-pixel windows, restored as one tile. Its dark capture is drawn with
//! Poisson-Gaussian noise of the Sony A7S2 at ISO 1600 (K 1.53 DN/e-, read
//! 6.3 DN on a 15,871 DN range) made 100x too dark, seeded.

use ndarray::Array3;
use pgrf_app::array::restore_array;
use pgrf_app::builtin::load_model;
use pgrf_nn::backend::DeviceKind;
use pgrf_nn::condition::NoiseLevel;
use pgrf_nn::infer::{SamplerChoice, Tiling};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal, Poisson};
use std::path::Path;

const H: usize = 384;
const W: usize = 512;
const RATIO: f64 = 100.0;
const RANGE: f64 = 15_871.0;
const K: f64 = 1.53;
const READ: f64 = 6.3;

/// The clean frame: every plane a ramp plus a slow diagonal wave, 0.03..0.21.
fn clean() -> Array3<f32> {
    Array3::from_shape_fn((4, H, W), |(p, y, x)| {
        let (yf, xf) = (y as f32, x as f32);
        0.04 + 0.12 * xf / W as f32
            + 0.04 * (yf / H as f32) * (p + 1) as f32 / 4.0
            + 0.02 * (xf / 97.0 + yf / 131.0).sin()
    })
}

/// The frame captured `RATIO` times too dark: electrons Poisson-drawn,
/// read noise Gaussian, normalised to the range (values below black kept).
fn capture(clean: &Array3<f32>, seed: u64) -> Array3<f32> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let read = Normal::new(0.0, READ).unwrap();
    clean.mapv(|v| {
        let electrons = v as f64 / RATIO * RANGE / K;
        let shot = Poisson::new(electrons.max(1e-9)).unwrap().sample(&mut rng);
        ((shot * K + read.sample(&mut rng)) / RANGE) as f32
    })
}

/// The noise level of [`capture`] as the DNG NoiseProfile states it.
fn level() -> NoiseLevel {
    NoiseLevel::from_normalised(K / RANGE, (READ / RANGE).powi(2), RATIO)
}

/// `name` restored as one tile, its flow (if any) sampled as `choice` says.
fn restore(name: &str, choice: SamplerChoice, dark: &Array3<f32>) -> Array3<f32> {
    let r = load_model(Path::new(name), choice, DeviceKind::Cpu).unwrap();
    let tiling = Tiling {
        tile: Some(W),
        overlap: None,
        seed: 0,
        device: DeviceKind::Cpu,
        kernels: Default::default(),
    };
    restore_array(
        r.as_ref(),
        dark.clone(),
        RATIO as f32,
        Some(level()),
        &tiling,
    )
    .unwrap()
}

/// Pixels where the flow's correction of its prior's restoration, summed
/// over the four planes, exceeds [`RING_DN`] of white: the ring-shaped
/// speckles the field draws (a ring is a few packed pixels across, a dark
/// and a light edge; every plane carries it, so the sum shows it while
/// plain noise partly cancels).
fn ring_pixels(flow: &Array3<f32>, prior: &Array3<f32>) -> usize {
    let d = (flow - prior).sum_axis(ndarray::Axis(0));
    d.iter().filter(|v| v.abs() > RING_DN).count()
}

/// The threshold of [`ring_pixels`], fraction of white: more than 10
/// robust sd of the built-in PGRF's correction on this frame (0.0017 at
/// its t2 of 0.1, 0.0023 at 0.5).
const RING_DN: f32 = 0.02;

#[test]
fn built_in_models_show_no_grid_and_no_ring_speckles_on_a_smooth_frame() {
    let clean = clean();
    let dark = capture(&clean, 51);
    let spc = restore("builtin:spc", SamplerChoice::default(), &dark);
    let pgrf = restore("builtin:pgrf", SamplerChoice::default(), &dark);
    let t05 = SamplerChoice {
        t2: Some(0.5),
        ..Default::default()
    };
    let pgrf_t05 = restore("builtin:pgrf", t05, &dark);
    let mut worst = Vec::new();
    for (name, out) in [
        ("SPC", &spc),
        ("PGRF", &pgrf),
        ("PGRF at t2 0.5", &pgrf_t05),
    ] {
        let seams = pgrf_eval::seams(out.view(), clean.view(), 128).unwrap();
        let rings = ring_pixels(out, &spc);
        eprintln!(
            "{name}: seams {seams}; ring pixels {rings}; {:.4}",
            seams.worst
        );
        worst.push((seams.worst, rings));
    }
    // The bar: no border of the 128-pixel windows (nor of anything
    // on that grid) steps more than 1.1x the median step. Measured: SPC
    // 1.04, PGRF 1.10 (its windows' statistics).
    assert!(worst[0].0 <= 1.1 && worst[1].0 <= 1.1, "{worst:?}");
    // The built-in PGRF (t2 0.1, chosen for this) draws no rings: 0 or 1
    // pixel here against 50-70 at t2 0.5, which shows the count sees them.
    assert!(worst[1].1 <= 2, "{worst:?}");
    assert!(worst[2].1 >= 20, "{worst:?}");
}
