//! Each noise component alone on flat images: sample statistics against
//! theory, with tolerances of 5 standard errors of the estimator (a false
//! failure rate below 1e-6 per check).

use ndarray::Array3;
use pgrf_noise::DarkLaw;
use pgrf_noise::{Capture, Components, Map, NoiseModel, PixelMaps, ReadDist};
use std::sync::Arc;

const RANGE: f32 = 15871.0;

fn model(components: &str) -> NoiseModel {
    NoiseModel {
        k: 1.53,
        read: ReadDist::Gaussian,
        maps: PixelMaps {
            bias: Map::Scalar(0.0),
            sigma_read: Map::Scalar(6.3),
            dark_rate: Map::Scalar(0.0),
            n_fp: Map::Scalar(0.0),
            dark_law: DarkLaw::Sqrt,
        },
        row_sigma: 0.99,
        quant_step: 1.0,
        components: Components::parse(components).unwrap(),
        dn_range: RANGE,
        black: Some(512.0),
        bank: None,
    }
}

fn capture(ratio: f32, seed: u64) -> Capture {
    Capture {
        ratio,
        exposure_s: 1.0,
        plane_rows: [0, 0, 1, 1],
        seed,
    }
}

/// Flat clean image whose short exposure carries `dn` DN of signal.
fn flat(dn: f32, ratio: f32, h: usize, w: usize) -> Array3<f32> {
    Array3::from_elem((4, h, w), dn * ratio / RANGE)
}

/// Back to DN of the short exposure.
fn to_dn(out: &Array3<f32>, ratio: f32) -> Vec<f64> {
    out.iter().map(|&v| (v * RANGE / ratio) as f64).collect()
}

fn mean_var(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let m = x.iter().sum::<f64>() / n;
    (
        m,
        x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0),
    )
}

/// |got - want| < 5 SE.
fn close(got: f64, want: f64, se: f64, what: &str) {
    assert!(
        (got - want).abs() < 5.0 * se,
        "{what}: got {got}, want {want} (5 SE = {})",
        5.0 * se
    );
}

#[test]
fn photon_shot_alone_has_variance_k_times_mean() {
    let (ratio, s) = (150.0, 200.0);
    let out = model("P")
        .sample(flat(s, ratio, 128, 128).view(), &capture(ratio, 1))
        .unwrap();
    let x = to_dn(&out, ratio);
    let (m, v) = mean_var(&x);
    let n = x.len() as f64;
    let k = 1.53f64;
    let var = k * s as f64;
    close(m, s as f64, (var / n).sqrt(), "shot mean");
    // Var of the sample variance for K*Poisson(S/K): K^4 (lambda + 2 lambda^2) / n, lambda = S/K.
    let lambda = s as f64 / k;
    close(
        v,
        var,
        (k.powi(4) * (lambda + 2.0 * lambda * lambda) / n).sqrt(),
        "shot variance",
    );
    // Values are multiples of K: photon counts times the gain.
    for &d in x.iter().take(1000) {
        let e = d / k;
        assert!((e - e.round()).abs() < 1e-3, "{d} is not a multiple of K");
    }
}

#[test]
fn read_noise_alone_is_gaussian_with_the_given_sigma() {
    let ratio = 100.0;
    let out = model("G")
        .sample(flat(50.0, ratio, 128, 128).view(), &capture(ratio, 2))
        .unwrap();
    let x = to_dn(&out, ratio);
    let (m, v) = mean_var(&x);
    let n = x.len() as f64;
    let sd = 6.3f64;
    close(m, 50.0, sd / n.sqrt(), "read mean");
    close(
        v,
        sd * sd,
        sd * sd * (2.0 / (n - 1.0)).sqrt(),
        "read variance",
    );
    // Fraction beyond 2 sigma: 4.55%.
    let tail = x.iter().filter(|d| (*d - 50.0).abs() > 2.0 * sd).count() as f64 / n;
    close(
        tail,
        0.0455,
        (0.0455 * 0.9545 / n).sqrt(),
        "2-sigma tail share",
    );
}

#[test]
fn row_noise_is_one_value_per_sensor_row() {
    let ratio = 100.0;
    let (h, w) = (512, 32);
    let out = model("H")
        .sample(flat(10.0, ratio, h, w).view(), &capture(ratio, 3))
        .unwrap();
    let x = to_dn(&out, ratio);
    let at = |p: usize, i: usize, j: usize| x[(p * h + i) * w + j];
    let mut row_values = Vec::new();
    for i in 0..h {
        // RGGB: R and G1 on sensor row 2i, G2 and B on 2i+1. Within a
        // sensor row every sample carries the same offset: no within-row variance.
        for j in 0..w {
            assert!((at(0, i, j) - at(0, i, 0)).abs() < 1e-3);
            assert!((at(1, i, j) - at(0, i, 0)).abs() < 1e-3);
            assert!((at(2, i, j) - at(3, i, 0)).abs() < 1e-3);
        }
        row_values.push(at(0, i, 0) - 10.0);
        row_values.push(at(2, i, 0) - 10.0);
    }
    let (m, v) = mean_var(&row_values);
    let n = row_values.len() as f64;
    let sd = 0.99f64;
    close(m, 0.0, sd / n.sqrt(), "row mean");
    close(
        v,
        sd * sd,
        sd * sd * (2.0 / (n - 1.0)).sqrt(),
        "variance of row offsets",
    );
}

#[test]
fn quantisation_alone_is_uniform_with_variance_q2_over_12() {
    let ratio = 100.0;
    let out = model("Q")
        .sample(flat(20.0, ratio, 128, 128).view(), &capture(ratio, 4))
        .unwrap();
    let x: Vec<f64> = to_dn(&out, ratio).into_iter().map(|d| d - 20.0).collect();
    assert!(x.iter().all(|d| d.abs() <= 0.5 + 1e-3));
    let (m, v) = mean_var(&x);
    let n = x.len() as f64;
    close(m, 0.0, (1.0f64 / 12.0 / n).sqrt(), "quantisation mean");
    // Uniform: mu4 = q^4/80; Var(s^2) = (mu4 - sigma^4)/n.
    close(
        v,
        1.0 / 12.0,
        ((1.0 / 80.0 - 1.0 / 144.0) / n).sqrt(),
        "quantisation variance",
    );
}

#[test]
fn dark_current_alone_and_with_fixed_pattern() {
    let ratio = 100.0;
    let (h, w) = (128, 128);
    let rate = 3.0f32; // electrons per sqrt(s)
    let t = 4.0f32; // 2 sqrt(s): 6 electrons
    let e = (rate * t.sqrt()) as f64;
    let k = 1.53f64;
    for (comps, nfp) in [("A", 0.0f32), ("AF", 0.25)] {
        let mut m = model(comps);
        m.maps.dark_rate = Map::Scalar(rate);
        m.maps.n_fp = Map::Scalar(nfp);
        let mut c = capture(ratio, 5);
        c.exposure_s = t;
        let out = m.sample(flat(0.0, ratio, h, w).view(), &c).unwrap();
        let x = to_dn(&out, ratio);
        let (mean, var) = mean_var(&x);
        let n = x.len() as f64;
        let g = k * (1.0 + nfp as f64);
        close(
            mean,
            g * e,
            (g * g * e / n).sqrt(),
            &format!("{comps} dark mean"),
        );
        close(
            var,
            g * g * e,
            (g.powi(4) * (e + 2.0 * e * e) / n).sqrt(),
            &format!("{comps} dark variance"),
        );
    }
    // Linear law: e = rate * t.
    let mut m = model("A");
    m.maps.dark_rate = Map::Scalar(rate);
    m.maps.dark_law = DarkLaw::Linear;
    let mut c = capture(ratio, 6);
    c.exposure_s = t;
    let x = to_dn(&m.sample(flat(0.0, ratio, h, w).view(), &c).unwrap(), ratio);
    let (mean, _) = mean_var(&x);
    let e = (rate * t) as f64;
    close(
        mean,
        k * e,
        (k * k * e / x.len() as f64).sqrt(),
        "linear-law dark mean",
    );
}

#[test]
fn fixed_pattern_offsets_land_on_their_pixels() {
    let ratio = 100.0;
    let (h, w) = (8, 8);
    let bias = Array3::from_shape_fn((4, h, w), |(p, i, j)| (p * 100 + i * 10 + j) as f32 * 0.1);
    let mut m = model("F");
    m.maps.bias = Map::Pixel(Arc::new(bias.clone()));
    let x = to_dn(
        &m.sample(flat(5.0, ratio, h, w).view(), &capture(ratio, 7))
            .unwrap(),
        ratio,
    );
    for (got, b) in x.iter().zip(bias.iter()) {
        assert!((got - 5.0 - *b as f64).abs() < 1e-3, "{got} vs {b}");
    }
    // noD: the same map collapsed to per-plane means.
    let g = m.maps.global();
    match g.bias {
        Map::Plane(v) => {
            for (p, mean) in v.iter().enumerate() {
                let want = bias.index_axis(ndarray::Axis(0), p).mean().unwrap();
                assert!((mean - want).abs() < 1e-4);
            }
        }
        other => panic!("expected per-plane means, got {other:?}"),
    }
}

#[test]
fn per_pixel_read_variances_are_honoured() {
    // Two kinds of pixel in one image: sigma 2 DN and sigma 8 DN (checkerboard),
    // over 400 independent captures.
    let ratio = 100.0;
    let (h, w) = (4, 4);
    let sig = Array3::from_shape_fn(
        (4, h, w),
        |(_, i, j)| if (i + j) % 2 == 0 { 2.0 } else { 8.0 },
    );
    let mut m = model("G");
    m.maps.sigma_read = Map::Pixel(Arc::new(sig.clone()));
    let draws = 400;
    let mut per_pixel: Vec<Vec<f64>> = vec![Vec::new(); 4 * h * w];
    for s in 0..draws {
        let x = to_dn(
            &m.sample(flat(30.0, ratio, h, w).view(), &capture(ratio, 1000 + s))
                .unwrap(),
            ratio,
        );
        for (acc, v) in per_pixel.iter_mut().zip(x) {
            acc.push(v);
        }
    }
    for (idx, (samples, s)) in per_pixel.iter().zip(sig.iter()).enumerate() {
        let (_, v) = mean_var(samples);
        let want = (*s as f64).powi(2);
        close(
            v,
            want,
            want * (2.0 / (draws as f64 - 1.0)).sqrt(),
            &format!("pixel {idx} variance"),
        );
    }
}

#[test]
fn same_seed_same_bytes_for_any_thread_count_and_seeds_differ() {
    let ratio = 200.0;
    let clean = Array3::from_shape_fn((4, 96, 80), |(p, i, j)| {
        ((p + i * 3 + j * 7) % 50) as f32 / 50.0
    });
    let mut m = model("PGHQFA");
    m.maps.dark_rate = Map::Scalar(2.0);
    m.maps.n_fp = Map::Plane([0.1, -0.1, 0.0, 0.05]);
    m.read = ReadDist::Tukey { lambda: -0.05 };
    let run = |threads: usize, seed: u64| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| m.sample(clean.view(), &capture(ratio, seed)).unwrap())
    };
    let one = run(1, 42);
    let two = run(2, 42);
    let four = run(4, 42);
    assert!(one
        .iter()
        .zip(two.iter())
        .all(|(a, b)| a.to_bits() == b.to_bits()));
    assert!(one
        .iter()
        .zip(four.iter())
        .all(|(a, b)| a.to_bits() == b.to_bits()));
    let other = run(2, 43);
    let differ = one.iter().zip(other.iter()).filter(|(a, b)| a != b).count();
    assert!(
        differ > one.len() / 2,
        "only {differ} values differ between seeds"
    );
}

#[test]
fn adc_range_is_respected() {
    let ratio = 100.0;
    // A clean value far beyond white clips at white; a negative read-noise
    // excursion below 0 DN clips at -black.
    let m = model("PG");
    let bright = m
        .sample(flat(20_000.0, ratio, 16, 16).view(), &capture(ratio, 8))
        .unwrap();
    assert!(
        bright.iter().all(|&v| (v - ratio).abs() < 1e-3),
        "not clipped at white"
    );
    let mut dark = model("G");
    dark.maps.sigma_read = Map::Scalar(2000.0);
    let x = to_dn(
        &dark
            .sample(flat(0.0, ratio, 32, 32).view(), &capture(ratio, 9))
            .unwrap(),
        ratio,
    );
    assert!(x.iter().all(|&d| d >= -512.0 - 1e-2));
    assert!(
        x.iter().any(|&d| (d + 512.0).abs() < 1e-2),
        "nothing reached the clip at 0 DN"
    );
}

#[test]
fn bad_inputs_are_errors() {
    let m = model("P");
    let c = flat(1.0, 100.0, 4, 4);
    let mut bad = capture(0.0, 1);
    assert!(m.sample(c.view(), &bad).is_err());
    bad = capture(100.0, 1);
    bad.exposure_s = f32::NAN;
    assert!(m.sample(c.view(), &bad).is_err());
    let mut nan = c.clone();
    nan[[1, 1, 1]] = f32::NAN;
    assert!(m.sample(nan.view(), &capture(100.0, 1)).is_err());
    let mut wrong = model("G");
    wrong.maps.sigma_read = Map::Pixel(Arc::new(Array3::zeros((4, 3, 3))));
    assert!(wrong
        .sample(c.view(), &capture(100.0, 1))
        .unwrap_err()
        .to_string()
        .contains("shape"));
    let mut neg = model("G");
    neg.maps.sigma_read = Map::Scalar(-1.0);
    assert!(neg.sample(c.view(), &capture(100.0, 1)).is_err());
}

/// With a noise bank, read, row and quantisation noise are the bank's
/// residuals: a dark capture (no signal) of the bank's size, components
/// G, H, Q, is in DN one bank frame's values per plane, each exactly once
/// (a shift of whole rows and columns), for every seed; another seed
/// draws another frame or shift.
#[test]
fn a_bank_draw_is_a_shifted_bank_frame() {
    use pgrf_noise::bank::NoiseBank;
    let frame = |k: usize| {
        Array3::from_shape_fn((4, 6, 10), |(p, i, j)| {
            ((k * 7919 + p * 613 + i * 71 + j * 13) % 97) as f32 - 48.0
        })
    };
    let bank = NoiseBank::new(vec![frame(1), frame(2), frame(3)]).unwrap();
    let mut m = model("G,H,Q");
    m.bank = Some(std::sync::Arc::new(bank.clone()));
    let zeros = Array3::<f32>::zeros((4, 6, 10));
    let mut seen = std::collections::HashSet::new();
    for seed in 0..8u64 {
        let c = Capture {
            ratio: 1.0,
            exposure_s: 0.01,
            plane_rows: [0, 0, 1, 1],
            seed,
        };
        let out = m.sample(zeros.view(), &c).unwrap();
        let dn: Vec<Vec<i64>> = (0..4)
            .map(|p| {
                let mut v: Vec<i64> = out
                    .index_axis(ndarray::Axis(0), p)
                    .iter()
                    .map(|&x| (x * RANGE).round() as i64)
                    .collect();
                v.sort_unstable();
                v
            })
            .collect();
        let which = bank.frames().iter().position(|f| {
            (0..4).all(|p| {
                let mut v: Vec<i64> = f
                    .index_axis(ndarray::Axis(0), p)
                    .iter()
                    .map(|&x| x.round() as i64)
                    .collect();
                v.sort_unstable();
                v == dn[p]
            })
        });
        assert!(which.is_some(), "seed {seed}: not one bank frame's values");
        seen.insert((which, out[[0, 0, 0]].to_bits()));
    }
    assert!(seen.len() > 1, "every seed drew the same frame and shift");
}
