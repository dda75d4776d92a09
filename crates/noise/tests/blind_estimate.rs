//! The blind noise estimate (`pgrf_noise::estimate`) on dark captures
//! synthesised from real mosaics (../shared/data/raw: the Canon 550D chart
//! DNG and the 768 x 512 DSLR crop), with the
//! Sony A7S2's noise (pgrf model: shot, read, row, quantisation, per-plane
//! dark-level offset) at ISO 400 to 12800 and exposure ratios 20 to 300:
//! K and the read noise found within 15 % of the parameters the capture
//! was drawn with. Seeded; the read noise compared is the square root of
//! read^2 + row^2 + 1/12: the two greens the estimator compares lie on
//! different rows, so row noise counts in full, as does the quantisation
//! step's.

use ndarray::Array3;
use pgrf_noise::estimate::fit;
use pgrf_noise::pair::{PairSpec, RatioSpec};
use pgrf_noise::{CameraProfile, ModelKind};
use pgrf_raw::{decode_file, pack_normalized, read_headerless, Cfa, HeaderlessSpec};

/// The capture (before amplification) of `clean` at `iso` and `ratio`, and
/// the (K, read) it was drawn with in DN.
fn capture(
    clean: &Array3<f32>,
    rows: [usize; 4],
    iso: u32,
    ratio: f32,
    seed: u64,
) -> (Array3<f32>, f64, f64, f64) {
    let mut spec = PairSpec::new(
        CameraProfile::built_in("sony-a7s2").unwrap(),
        ModelKind::Pgrf,
    );
    spec.iso = Some(iso);
    spec.ratio = RatioSpec::Fixed(ratio);
    let pair = spec.synthesize(clean.view(), rows, seed).unwrap();
    let range = spec.dn_range();
    let p = &pair.params;
    let read = (p.sigma_gauss.powi(2) + p.sigma_row.powi(2) + 1.0 / 12.0).sqrt();
    (pair.noisy.mapv(|v| v / ratio), p.k, read, range)
}

fn check(name: &str, clean: &Array3<f32>, rows: [usize; 4]) -> Vec<String> {
    // The clean mosaic is a real capture with noise of its own, S_c c +
    // O_c at its level c; divided by the ratio r it adds S_c / r to the
    // dark capture's S and O_c / r^2 to its O. Measured on the clean frame
    // by the same estimator (its noise is far below the captures').
    let own = fit(clean.view()).unwrap();
    let mut lines = Vec::new();
    let mut failures: Vec<String> = Vec::new();
    let mut seed = 1;
    for iso in [400, 1600, 6400, 12800] {
        for ratio in [20.0f32, 100.0, 300.0] {
            seed += 1;
            let (cap, k, read, range) = capture(clean, rows, iso, ratio, seed);
            let f = fit(cap.view()).unwrap();
            let (k_est, read_est) = f.in_dn(range);
            let r = ratio as f64;
            let k = k + own.s / r * range;
            let read = (read * read + own.o / (r * r) * range * range).sqrt();
            let (ek, er) = (k_est / k - 1.0, read_est / read - 1.0);
            lines.push(format!(
                "{name} ISO {iso} x{ratio}: K {k_est:.3} vs {k:.3} ({:+.1} %), read {read_est:.2} vs {read:.2} ({:+.1} %), {} blocks",
                100.0 * ek,
                100.0 * er,
                f.blocks
            ));
            if ek.abs() >= 0.15 || er.abs() >= 0.15 {
                failures.push(lines.last().unwrap().clone());
            }
        }
    }
    for l in &lines {
        eprintln!("{l}");
    }
    failures
}

fn clipped(frame: &pgrf_raw::RawFrame) -> (Array3<f32>, [usize; 4]) {
    let packed = pack_normalized(frame, true).unwrap();
    (packed, frame.cfa.offsets().map(|(r, _)| r))
}

#[test]
#[cfg_attr(not(shared_data), ignore = "needs ../shared/data")]
fn the_blind_estimate_finds_k_and_read_noise_of_real_mosaics() {
    let data = pgrf_core::shared_data_dir().expect("shared data");
    let chart = decode_file(
        &data.join("raw/canon550d_colorchart.dng"),
        &Default::default(),
    )
    .unwrap();
    let crop = read_headerless(
        &data.join("raw/dslr_crop_768x512_rggb14.raw"),
        &HeaderlessSpec {
            width: 768,
            height: 512,
            bits: 14,
            cfa: Some(Cfa::Rggb),
            black: vec![600.0],
            white: Some(15520),
            big_endian: false,
        },
    )
    .unwrap();
    let mut failures = Vec::new();
    for (name, frame) in [("550D chart", &chart), ("DSLR crop", &crop)] {
        let (clean, rows) = clipped(frame);
        failures.extend(check(name, &clean, rows));
    }
    // The conditions the estimator does not yet meet within 15 % (MODELS.md,
    // "Blind noise estimate"): the darkest corner (ISO 12800 at x300, about
    // one electron per pixel: the discrete shot noise's block variances
    // spread wider than the Gaussian calibration of the quartile assumes, so
    // K comes out low), and the small DSLR crop's bright, low-noise captures
    // (its fine texture survives the green difference and lifts K). Any
    // other condition failing, or one of these passing, fails the test.
    let known: Vec<&str> = vec![
        "550D chart ISO 12800 x300",
        "DSLR crop ISO 400 x20",
        "DSLR crop ISO 400 x100",
        "DSLR crop ISO 1600 x20",
        "DSLR crop ISO 12800 x300",
    ];
    let failed: Vec<&str> = failures
        .iter()
        .map(|l| l.split(':').next().unwrap())
        .collect();
    assert_eq!(failed, known, "{failures:#?}");
}
