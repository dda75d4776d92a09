//! Issue 51, lever 6: the built-in models restore a small seeded frame
//! without a grid at the flow's internal windows, without ring-shaped
//! speckles, and as well at its edge as inside, measured with `pgrf_eval`'s
//! artefact metrics and the error by distance to the edge.
//!
//! The frame is smooth (gentle ramps and a slow wave, no structure on any
//! grid, so that a step of the error at a window border is the network's
//! and not the picture's), 384 x 512 packed pixels: 3 x 4 of the PGRF's
//! 128-pixel windows, restored as one tile. Its dark capture is drawn with
//! Poisson-Gaussian noise of the Sony A7S2 at ISO 1600 (K 1.53 DN/e-, read
//! 6.3 DN on a 15,871 DN range) made 100x too dark, seeded.

use ndarray::{s, Array3};
use pgrf_app::array::restore_array;
use pgrf_app::builtin::load_model;
use pgrf_nn::backend::DeviceKind;
use pgrf_nn::condition::NoiseLevel;
use pgrf_nn::infer::image::EDGE_MARGIN;
use pgrf_nn::infer::{SamplerChoice, Tiling};
use pgrf_nn::weights::read_meta;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal, Poisson};
use std::path::{Path, PathBuf};

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

/// The built-in PGRF's prior, the SPC its configuration names (the file its
/// field was trained to correct, which need not be today's built-in SPC).
fn flow_prior() -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let meta = read_meta(&root.join("models/pgrf.safetensors")).unwrap();
    let cfg = meta.training.and_then(|t| t.config).expect("a record");
    root.join(cfg.prior.expect("a prior"))
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
    let prior_file = flow_prior();
    let prior = restore(
        prior_file.to_str().unwrap(),
        SamplerChoice::default(),
        &dark,
    );
    let pgrf = restore("builtin:pgrf", SamplerChoice::default(), &dark);
    let t05 = SamplerChoice {
        t2: Some(0.5),
        ..Default::default()
    };
    let pgrf_t05 = restore("builtin:pgrf", t05, &dark);
    // The windows sit on the grid of the frame mirrored by EDGE_MARGIN; the
    // last border, 4 pixels from the frame's edge, lies in the edge band
    // that the edge test below bounds, so the grid is also measured on the
    // frame less that band.
    let inside = s![.., ..H - 2 * EDGE_MARGIN, ..W - 2 * EDGE_MARGIN];
    let mut worst = Vec::new();
    for (name, out) in [
        ("SPC", &spc),
        ("PGRF", &pgrf),
        ("PGRF at t2 0.5", &pgrf_t05),
    ] {
        let whole = pgrf_eval::seams(out.view(), clean.view(), 128, EDGE_MARGIN).unwrap();
        let within =
            pgrf_eval::seams(out.slice(inside), clean.slice(inside), 128, EDGE_MARGIN).unwrap();
        // (For the SPC: the pixels where it differs from the flow's prior
        // by as much.)
        let rings = ring_pixels(out, &prior);
        eprintln!("{name}: seams {whole}; inside the edge band {within}; ring pixels {rings}");
        worst.push((within.worst, rings));
    }
    // The bar is 1.1x the median step at every border of the
    // 128-pixel windows. The SPC has no windows (one tile): 1.02 inside the
    // edge band, 1.24 with it (row 380). The built-in PGRF, whose windows'
    // GroupNorm statistics stepped at their borders, measured 1.10 inside
    // the band (1.18 at t2 0.5; the PGRF before it 1.14 on the whole grid);
    // with them blended across the borders (`NormSpec::blend`) 1.03 (1.07),
    // and 1.20 with the band (row 380, as its prior's 1.24).
    assert!(worst.iter().all(|w| w.0 <= 1.1), "{worst:?}");
    // The built-in PGRF (t2 0.1, chosen for this) draws no rings: none here
    // against 25 at t2 0.5, which shows the count sees them (31 with the
    // stepping statistics). Blending the statistics over whole windows,
    // centre to centre, drew 162 and 538: the network learnt each window's
    // own statistics; blended over an eighth of a window each side of a
    // border it draws none.
    assert!(worst[1].1 <= 2, "{worst:?}");
    assert!(worst[2].1 >= 20, "{worst:?}");
}

/// Mean |error| of the pixels `lo..hi` packed pixels from the frame's
/// nearest edge, over the four planes.
fn edge_band_error(out: &Array3<f32>, clean: &Array3<f32>, lo: usize, hi: usize) -> f64 {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for ((p, y, x), &o) in out.indexed_iter() {
        let d = y.min(x).min(H - 1 - y).min(W - 1 - x);
        if (lo..hi).contains(&d) {
            sum += (o - clean[[p, y, x]]).abs() as f64;
            n += 1;
        }
    }
    sum / n as f64
}

/// The frame's outermost packed rows and columns are restored nearly as
/// well as its inside: the networks' zero padding had left them half noisy
/// (5.4x the interior's mean |error| for the outermost ring, 1.8x for the
/// next, before the frame was mirrored by `EDGE_MARGIN` pixels); now within
/// 1.6x (measured 1.27x to 1.36x for the three outer bands, both models).
#[test]
fn the_frames_edge_is_restored_like_its_inside() {
    let clean = clean();
    let dark = capture(&clean, 51);
    for name in ["builtin:spc", "builtin:pgrf"] {
        let out = restore(name, SamplerChoice::default(), &dark);
        let inside = edge_band_error(&out, &clean, 48, usize::MAX);
        let ratios: Vec<f64> = [(0, 1), (1, 2), (2, 4)]
            .iter()
            .map(|&(lo, hi)| edge_band_error(&out, &clean, lo, hi) / inside)
            .collect();
        eprintln!("{name}: edge bands' mean |error| over the inside's {ratios:.3?}");
        assert!(ratios.iter().all(|&r| r < 1.6), "{name}: {ratios:?}");
    }
}
