//! `pgrf metrics` as scripts see it: DNGs in, one line of scores (or one
//! line of error) out.

mod common;
use common::{one_line_error, pgrf, s};

use pgrf_raw::{write_dng, Cfa, DngOptions, RawFrame};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Output;

const W: usize = 96;
const H: usize = 64;
const BLACK: f32 = 512.0;
const WHITE: u32 = 16383;
/// DN added to the perturbed pixels.
const BUMP: u16 = 40;

fn scratch(name: &str) -> PathBuf {
    common::scratch("metrics", name)
}

/// A deterministic scene well inside black..white.
fn reference_mosaic(w: usize, h: usize) -> Vec<u16> {
    (0..w * h)
        .map(|k| {
            let (y, x) = (k / w, k % w);
            BLACK as u16 + 100 + ((x * 37 + y * 91 + x * y) % 9000) as u16
        })
        .collect()
}

/// Every third pixel (by x + y) BUMP DN brighter.
fn is_bumped(k: usize, w: usize) -> bool {
    (k / w + k % w).is_multiple_of(3)
}

fn write(dir: &Path, name: &str, w: usize, h: usize, cfa: Cfa, mosaic: Vec<u16>) -> PathBuf {
    let f = RawFrame::from_mosaic(w, h, mosaic, cfa, [BLACK; 4], WHITE).unwrap();
    let p = dir.join(name);
    write_dng(&f, &p, &DngOptions::default()).unwrap();
    p
}

fn json(out: &Output) -> Value {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout.clone()).unwrap();
    assert_eq!(text.trim_end().lines().count(), 1, "{text}");
    assert!(text.starts_with("{\"psnr\":"), "psnr first: {text}");
    serde_json::from_str(&text).unwrap()
}

/// ELD protocol PSNR written out from the definition: per-sample
/// normalisation as `pack_normalized` does it in f32, clamp, x255 in f32,
/// squared differences and mean in f64.
fn psnr_by_formula(a: &[u16], b: &[u16]) -> f64 {
    let scale = 1.0 / (WHITE as f32 - BLACK);
    let v = |d: u16| ((d as f32 - BLACK) * scale).clamp(0.0, 1.0) * 255.0;
    // The mosaic dimensions are even, so every sample is in some plane.
    let mse = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| {
            let d = v(x) as f64 - v(y) as f64;
            d * d
        })
        .sum::<f64>()
        / a.len() as f64;
    10.0 * (255.0f64 * 255.0 / mse).log10()
}

#[test]
fn identical_files_score_infinite_psnr_and_unit_ssim() {
    let dir = scratch("identical");
    let r = write(&dir, "ref.dng", W, H, Cfa::Rggb, reference_mosaic(W, H));
    let v = json(&pgrf(&["metrics", s(&r), s(&r), "--json"]));
    // JSON has no infinity: an infinite PSNR is null.
    assert_eq!(v["psnr"], Value::Null);
    assert_eq!(v["ssim"], 1.0);
    assert_eq!(v["gain"], Value::Null);
    assert!(v["protocol"].as_str().unwrap().contains("x255"), "{v}");
    // No error, no artefact: no speckle, and no seam asked for.
    assert_eq!(v["speckles"]["count"], 0, "{v}");
    assert_eq!(v["seam"], Value::Null);
    let v = json(&pgrf(&[
        "metrics",
        s(&r),
        s(&r),
        "--seam-period",
        "8",
        "--json",
    ]));
    assert_eq!(
        (
            v["seam"]["worst"].as_f64(),
            v["seam"]["median_step"].as_f64()
        ),
        (Some(0.0), Some(0.0)),
        "{v}"
    );
    // The grid's offset is below its period, and only with a period.
    for (args, needle) in [
        (
            vec!["--seam-period", "8", "--seam-offset", "8"],
            "offset must be below the period",
        ),
        (vec!["--seam-offset", "3"], "--seam-period"),
    ] {
        let mut all = vec!["metrics", s(&r), s(&r)];
        all.extend(args);
        let out = pgrf(&all);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.starts_with("pgrf: error:") && err.contains(needle),
            "{err}"
        );
    }
    let out = pgrf(&["metrics", s(&r), s(&r)]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("PSNR     inf"), "{text}");
    assert!(text.contains("SSIM     1.000000"), "{text}");
    assert!(text.contains("protocol "), "{text}");
}

#[test]
fn known_perturbation_gives_the_formula_psnr() {
    let dir = scratch("perturbed");
    let clean = reference_mosaic(W, H);
    let bumped: Vec<u16> = clean
        .iter()
        .enumerate()
        .map(|(k, &v)| if is_bumped(k, W) { v + BUMP } else { v })
        .collect();
    let r = write(&dir, "ref.dng", W, H, Cfa::Rggb, clean.clone());
    let o = write(&dir, "out.dng", W, H, Cfa::Rggb, bumped.clone());
    let want = psnr_by_formula(&bumped, &clean);
    // Closed form as a sanity check of the formula itself: a third of the
    // samples off by BUMP / (white - black) of full scale.
    let n_bumped = (0..W * H).filter(|&k| is_bumped(k, W)).count() as f64;
    let step = BUMP as f64 * 255.0 / (WHITE as f64 - BLACK as f64);
    let closed = 10.0 * (255.0f64 * 255.0 / (n_bumped / (W * H) as f64 * step * step)).log10();
    assert!((want - closed).abs() < 1e-4, "{want} vs {closed}");

    let v = json(&pgrf(&["metrics", s(&o), s(&r), "--json"]));
    let got = v["psnr"].as_f64().unwrap();
    assert!((got - want).abs() <= 1e-6, "pgrf {got} vs formula {want}");
    let ssim = v["ssim"].as_f64().unwrap();
    assert!(ssim > 0.5 && ssim < 1.0, "{ssim}");

    // The least-squares gain can only lower the squared error here (nothing
    // saturated, gain below 1 so nothing clips).
    let c = json(&pgrf(&[
        "metrics",
        s(&o),
        s(&r),
        "--json",
        "--illuminance-correct",
    ]));
    let gain = c["gain"].as_f64().unwrap();
    assert!(gain < 1.0 && gain > 0.99, "{gain}");
    assert!(c["psnr"].as_f64().unwrap() >= got - 1e-9, "{c} vs {v}");
    assert!(
        c["protocol"].as_str().unwrap().contains("correction on"),
        "{c}"
    );
}

fn assert_one_line_failure(out: &Output, names: &[&str]) {
    let err = one_line_error(out);
    assert!(
        out.stdout.is_empty(),
        "stdout: {}",
        String::from_utf8_lossy(&out.stdout)
    );
    assert_eq!(err.trim_end().lines().count(), 1, "not one line: {err:?}");
    assert!(err.starts_with("pgrf: error: "), "{err}");
    for n in names {
        assert!(err.contains(n), "error does not mention {n}: {err}");
    }
}

#[test]
fn different_sizes_or_cfa_are_refused_in_one_line() {
    let dir = scratch("mismatch");
    let r = write(&dir, "ref.dng", W, H, Cfa::Rggb, reference_mosaic(W, H));
    let wide = write(
        &dir,
        "wide.dng",
        W + 2,
        H,
        Cfa::Rggb,
        reference_mosaic(W + 2, H),
    );
    let out = pgrf(&["metrics", s(&wide), s(&r), "--json"]);
    assert_one_line_failure(&out, &["wide.dng", "98x64", "96x64"]);
    let bggr = write(&dir, "bggr.dng", W, H, Cfa::Bggr, reference_mosaic(W, H));
    let out = pgrf(&["metrics", s(&bggr), s(&r)]);
    assert_one_line_failure(&out, &["bggr.dng", "BGGR", "RGGB"]);
    let out = pgrf(&["metrics", s(&dir.join("missing.dng")), s(&r)]);
    assert_one_line_failure(&out, &["missing.dng"]);
}
