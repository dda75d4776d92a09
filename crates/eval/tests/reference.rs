//! pgrf-eval against scikit-image.
//!
//! The expected numbers below were produced by
//! `tests/reference/metrics_reference.py` (numpy 2.4.6, scikit-image 0.26.0,
//! scipy 1.17.1) from inputs this file regenerates bit for bit (checked by the
//! FNV-1a hashes the script prints). To reproduce them:
//!
//! ```text
//! python3 -m venv /tmp/skvenv && /tmp/skvenv/bin/pip install scikit-image numpy
//! /tmp/skvenv/bin/python tests/reference/metrics_reference.py
//! ```
//!
//! Tolerance: 1e-6 dB for PSNR and 1e-6 for SSIM (the agreement observed is
//! below 1e-12). scikit-image is run on float64 copies of the float32 x255
//! images; its float32 path (what ELD literally calls) differs from these by
//! up to 4e-6 in SSIM, which the script also prints.

use ndarray::Array3;
use pgrf_eval::{
    evaluate, illuminance_correct, illuminance_gain, psnr, ssim, MetricError, Protocol, SsimOptions,
};

/// Knuth's MMIX LCG, advanced before each draw; 24 high bits -> [0, 1) exactly.
struct Lcg(u64);

impl Lcg {
    fn next_f32(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 40) as f32 / 16_777_216.0
    }
}

/// The script's `pattern`: integer arithmetic, then one f32 division.
fn pattern(c: usize, h: usize, w: usize) -> Array3<f32> {
    Array3::from_shape_fn((c, h, w), |(ch, i, j)| {
        let tri = ((i + 2 * j + 16 * ch) % 512).abs_diff(256);
        let num = 4 * tri + (7 * i + 3 * j) % 41;
        num as f32 / 1100.0
    })
}

type Rect = ((usize, usize), (usize, usize));

/// The script's `make_case`: `output = gain * reference + (u - 0.5) * amp`,
/// one f32 operation at a time, then the optional saturated rectangle.
fn make_case(
    shape: (usize, usize, usize),
    seed: u64,
    amp: f32,
    gain: f32,
    saturate: Option<Rect>,
) -> (Array3<f32>, Array3<f32>) {
    let (c, h, w) = shape;
    let mut reference = pattern(c, h, w);
    let mut rng = Lcg(seed);
    let u = Array3::from_shape_simple_fn(shape, || rng.next_f32());
    let mut out = Array3::from_shape_fn(shape, |ix| gain * reference[ix] + (u[ix] - 0.5) * amp);
    if let Some(((y0, y1), (x0, x1))) = saturate {
        for ch in 0..c {
            for i in y0..y1 {
                for j in x0..x1 {
                    reference[[ch, i, j]] = 1.0;
                    out[[ch, i, j]] = 0.25 + u[[ch, i, j]] * 0.5;
                }
            }
        }
    }
    (out, reference)
}

/// FNV-1a 64 over the little-endian bytes of the values in C order.
fn fnv1a(a: &Array3<f32>) -> u64 {
    let mut h: u64 = 0xcbf29ce484222325;
    for v in a.iter() {
        for b in v.to_le_bytes() {
            h = (h ^ b as u64).wrapping_mul(0x100000001b3);
        }
    }
    h
}

struct Expected {
    name: &'static str,
    shape: (usize, usize, usize),
    seed: u64,
    amp: f32,
    gain_applied: f32,
    saturate: Option<Rect>,
    out_fnv: u64,
    ref_fnv: u64,
    /// (PSNR, SSIM): no clamping, x255 as given.
    raw: (f64, f64),
    /// ELD protocol without and with the illuminance correction.
    eld: (f64, f64),
    eld_corrected: (f64, f64),
    /// The fitted gain (float64 sums in the script).
    gain: f64,
}

const CASES: &[Expected] = &[
    Expected {
        name: "smooth_64x80",
        shape: (4, 64, 80),
        seed: 1,
        amp: 0.1,
        gain_applied: 1.0,
        saturate: None,
        out_fnv: 0xa6dbbc0c55a08004,
        ref_fnv: 0x24aaac9b550089ad,
        raw: (30.8184683246478, 0.668169136057966),
        eld: (30.822975092537884, 0.6682458717160209),
        eld_corrected: (30.83777150675113, 0.6693788318015255),
        gain: 0.9966416991365855,
    },
    Expected {
        name: "odd_45x59",
        shape: (4, 45, 59),
        seed: 2,
        amp: 0.3,
        gain_applied: 1.0,
        saturate: None,
        out_fnv: 0x7c0fc08bae250309,
        ref_fnv: 0x2afc989f5e57f52f,
        raw: (21.317197553438984, 0.18562992694251995),
        eld: (21.326290023950513, 0.18568658051736814),
        eld_corrected: (21.412902698403826, 0.1904580278957605),
        gain: 0.9797504827789214,
    },
    Expected {
        name: "small_9x11",
        shape: (4, 9, 11),
        seed: 3,
        amp: 0.05,
        gain_applied: 1.0,
        saturate: None,
        out_fnv: 0x1afe3f2e296ed047,
        ref_fnv: 0x2d9fa8fbbe45b628,
        raw: (37.00798808562202, 0.8884473356317522),
        eld: (37.00798808562202, 0.8884473356317522),
        eld_corrected: (37.014481607338936, 0.8885506284080364),
        gain: 0.9993299593786029,
    },
    Expected {
        name: "exact_7x7",
        shape: (4, 7, 7),
        seed: 4,
        amp: 0.2,
        gain_applied: 1.0,
        saturate: None,
        out_fnv: 0x96be3f92642cf249,
        ref_fnv: 0x52d56e1dc5c4eaea,
        raw: (24.49699561537717, 0.31688880307313516),
        eld: (24.538277498133855, 0.3180069522519033),
        eld_corrected: (24.599629903153488, 0.32085756623531103),
        gain: 0.9915903229753594,
    },
    Expected {
        name: "saturated_40x50",
        shape: (4, 40, 50),
        seed: 5,
        amp: 0.05,
        gain_applied: 1.0,
        saturate: Some(((10, 25), (12, 30))),
        out_fnv: 0x71212c8ecbf7ff68,
        ref_fnv: 0x0f6030e0370b6d36,
        raw: (14.42349004393786, 0.49322524587345207),
        eld: (14.42349004393786, 0.49322524587345207),
        eld_corrected: (14.422103349098181, 0.49325161530533607),
        gain: 0.9998137417770794,
    },
    Expected {
        name: "gain_48x52",
        shape: (4, 48, 52),
        seed: 6,
        amp: 0.02,
        gain_applied: 0.8,
        saturate: None,
        out_fnv: 0x75e10bcedcc68736,
        ref_fnv: 0x40c71fe6dc141882,
        raw: (18.307336256225124, 0.9451711275210074),
        eld: (18.307336256225124, 0.9451711275210074),
        eld_corrected: (42.85272964916253, 0.9699917049052275),
        gain: 1.2499892504452055,
    },
    Expected {
        name: "one_channel_16x13",
        shape: (1, 16, 13),
        seed: 7,
        amp: 0.1,
        gain_applied: 1.0,
        saturate: None,
        out_fnv: 0xd036794d79411cc4,
        ref_fnv: 0xab20cf29fa34047d,
        raw: (30.75166175222443, 0.6701823939273114),
        eld: (30.75166175222443, 0.6701823939273114),
        eld_corrected: (30.766493103620654, 0.6695201405141056),
        gain: 1.0019319171856012,
    },
];

const TOL: f64 = 1e-6;

fn close(what: &str, got: f64, want: f64) {
    assert!(
        (got - want).abs() <= TOL,
        "{what}: got {got:.15}, scikit-image {want:.15} (diff {:.3e})",
        got - want
    );
}

fn build(e: &Expected) -> (Array3<f32>, Array3<f32>) {
    make_case(e.shape, e.seed, e.amp, e.gain_applied, e.saturate)
}

#[test]
fn inputs_are_bit_identical_to_the_scripts() {
    for e in CASES {
        let (out, reference) = build(e);
        assert_eq!(fnv1a(&out), e.out_fnv, "{} output", e.name);
        assert_eq!(fnv1a(&reference), e.ref_fnv, "{} reference", e.name);
    }
}

#[test]
fn scores_match_scikit_image() {
    let raw = Protocol {
        clamp: false,
        ..Protocol::eld(false)
    };
    for e in CASES {
        let (out, reference) = build(e);
        for (label, proto, want) in [
            ("raw", &raw, e.raw),
            ("eld", &Protocol::eld(false), e.eld),
            ("eld_corrected", &Protocol::eld(true), e.eld_corrected),
        ] {
            let s = evaluate(out.view(), reference.view(), proto).unwrap();
            close(&format!("{} {label} PSNR", e.name), s.psnr, want.0);
            close(&format!("{} {label} SSIM", e.name), s.ssim, want.1);
        }
        let s = evaluate(out.view(), reference.view(), &Protocol::eld(true)).unwrap();
        close(&format!("{} gain", e.name), s.gain.unwrap(), e.gain);
    }
}

#[test]
fn plain_psnr_and_ssim_on_x255_images_match_scikit_image() {
    // The "raw" column is scikit-image on x255 float32 images without clamping:
    // the standalone functions must give it directly.
    let o = SsimOptions::skimage(255.0);
    for e in CASES {
        let (out, reference) = build(e);
        let (o255, r255) = (out.mapv(|v| v * 255.0), reference.mapv(|v| v * 255.0));
        close(
            &format!("{} psnr()", e.name),
            psnr(o255.view(), r255.view(), 255.0).unwrap(),
            e.raw.0,
        );
        close(
            &format!("{} ssim()", e.name),
            ssim(o255.view(), r255.view(), &o).unwrap(),
            e.raw.1,
        );
    }
}

#[test]
fn illuminance_correction_recovers_a_known_gain() {
    // A noiseless copy at 0.8x brightness: the fitted gain is 1/0.8 up to the
    // f32 rounding of the copy, and the corrected copy is the reference.
    let reference = pattern(4, 30, 37);
    let out = reference.mapv(|v| v * 0.8);
    let (corrected, g) = illuminance_correct(out.view(), reference.view()).unwrap();
    assert!((g.gain - 1.25).abs() < 1e-6, "gain {}", g.gain);
    assert_eq!(g.pixels, reference.len());
    let worst = corrected
        .iter()
        .zip(reference.iter())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(
        worst < 1e-6,
        "corrected differs from the reference by {worst}"
    );
    let s = evaluate(out.view(), reference.view(), &Protocol::eld(true)).unwrap();
    assert!(s.psnr > 110.0, "{}", s.psnr);
    let s = evaluate(out.view(), reference.view(), &Protocol::eld(false)).unwrap();
    assert!(s.psnr < 30.0, "{}", s.psnr);
}

#[test]
fn saturated_reference_pixels_do_not_move_the_gain() {
    let clean = pattern(4, 30, 37);
    let out = clean.mapv(|v| v * 0.8);
    // Saturate a block of the reference and put wrong output values there.
    let with_block = |ref_value: f32, out_value: f32| {
        let (mut r, mut o) = (clean.clone(), out.clone());
        for ch in 0..4 {
            for i in 5..20 {
                for j in 3..25 {
                    r[[ch, i, j]] = ref_value;
                    o[[ch, i, j]] = out_value;
                }
            }
        }
        illuminance_gain(o.view(), r.view()).unwrap()
    };
    let a = with_block(1.0, 0.05);
    let b = with_block(1.0, 0.9);
    assert_eq!(a, b, "masked pixels changed the fit");
    assert!((a.gain - 1.25).abs() < 1e-6, "gain {}", a.gain);
    assert_eq!(a.pixels, clean.len() - 4 * 15 * 22);
    // The same block just below saturation does count, and drags the gain off.
    let c = with_block(0.999, 0.05);
    assert!((c.gain - 1.25).abs() > 0.05, "gain {}", c.gain);
}

#[test]
fn identical_images() {
    let (out, _) = build(&CASES[0]);
    assert_eq!(psnr(out.view(), out.view(), 255.0).unwrap(), f64::INFINITY);
    let s = evaluate(out.view(), out.view(), &Protocol::eld(true)).unwrap();
    assert_eq!((s.psnr, s.ssim), (f64::INFINITY, 1.0));
}

#[test]
fn bad_inputs_are_one_line_errors() {
    let a = Array3::<f32>::zeros((4, 10, 12));
    let b = Array3::<f32>::zeros((4, 12, 10));
    let e = evaluate(a.view(), b.view(), &Protocol::eld(false)).unwrap_err();
    assert!(matches!(e, MetricError::ShapeMismatch { .. }));
    assert_eq!(
        e.to_string(),
        "output has shape [4, 10, 12] but reference has shape [4, 12, 10]; metrics need equal shapes"
    );
    let mut c = a.clone();
    c[[2, 3, 5]] = f32::NAN;
    let e = evaluate(a.view(), c.view(), &Protocol::eld(false))
        .unwrap_err()
        .to_string();
    assert_eq!(
        e,
        "reference holds NaN at [2, 3, 5]; metrics need finite values"
    );
    c[[2, 3, 5]] = f32::INFINITY;
    let e = psnr(c.view(), a.view(), 255.0).unwrap_err().to_string();
    assert_eq!(
        e,
        "output holds inf at [2, 3, 5]; metrics need finite values"
    );
    // scikit-image refuses planes smaller than the window (the script checks).
    let small = Array3::<f32>::zeros((4, 6, 10));
    let e = evaluate(small.view(), small.view(), &Protocol::eld(false)).unwrap_err();
    assert_eq!(
        e,
        MetricError::TooSmall {
            h: 6,
            w: 10,
            win: 7
        }
    );
    for e in [
        evaluate(a.view(), b.view(), &Protocol::eld(false))
            .unwrap_err()
            .to_string(),
        e.to_string(),
    ] {
        assert!(!e.contains('\n'), "{e}");
    }
}
