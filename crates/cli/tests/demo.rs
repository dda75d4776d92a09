//! `pgrf demo` end to end at a reduced size with the built-in models, on the
//! procedural scene and on a centre window of the built-in photograph: the
//! JSON contract, the models beating the noisy input by stated margins, the
//! shipped weights reproducing the scores MODELS.md records, the files it
//! writes, and its refusals.

mod common;

use common::{one_line_error, pgrf, s, scratch};
use serde_json::Value;
use std::path::Path;

/// The reduced procedural demo (MODELS.md, "Check").
const SIZE: &str = "384x256";
/// The centre window of the built-in photograph the photo tests run on.
const PHOTO_SIZE: &str = "512x384";

fn run_demo(dir: &Path) -> Value {
    run_scene(dir, &["--scene", "procedural", "--size", SIZE])
}

fn run_scene(dir: &Path, scene: &[&str]) -> Value {
    let mut args = vec!["demo", "-o", s(dir), "--json", "--quiet"];
    args.extend_from_slice(scene);
    let out = pgrf(&args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "demo failed: {err}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let last = stdout.lines().last().expect("a JSON line");
    // The table and header go to stderr: stdout is exactly one line.
    assert_eq!(stdout.lines().count(), 1, "{stdout}");
    assert!(
        err.contains("PSNR / SSIM")
            && err.contains("protocol:")
            && err.contains("the camera counts as calibrated"),
        "{err}"
    );
    serde_json::from_str(last).unwrap()
}

fn psnr(v: &Value, ratio: &str, method: &str) -> f64 {
    v[ratio][method]["psnr"].as_f64().unwrap()
}

fn ssim(v: &Value, ratio: &str, method: &str) -> f64 {
    v[ratio][method]["ssim"].as_f64().unwrap()
}

#[test]
fn demo_models_beat_the_noisy_input_and_write_every_file() {
    let dir = scratch("demo", "e2e");
    let v = run_demo(&dir);
    let keys: Vec<&str> = v.as_object().unwrap().keys().map(|k| k.as_str()).collect();
    assert_eq!(keys, ["seconds", "x100", "x200"]);
    assert!(v["seconds"].as_f64().unwrap() > 0.0);
    for ratio in ["x100", "x200"] {
        let noisy = psnr(&v, ratio, "noisy");
        for (method, margin) in [("spc", SPC_MARGIN_DB), ("pgrf", PGRF_MARGIN_DB)] {
            let got = psnr(&v, ratio, method);
            assert!(
                got >= noisy + margin,
                "{ratio} {method}: {got:.2} dB, noisy input {noisy:.2} dB (margin {margin} dB)"
            );
            assert!(
                ssim(&v, ratio, method) > ssim(&v, ratio, "noisy") + 0.05,
                "{ratio} {method} SSIM {v}"
            );
        }
        // x200 is the harder capture.
        assert!(psnr(&v, "x200", "noisy") < psnr(&v, "x100", "noisy"));
    }
    for name in [
        "clean",
        "noisy_x100",
        "spc_x100",
        "pgrf_x100",
        "noisy_x200",
        "spc_x200",
        "pgrf_x200",
    ] {
        let f = pgrf_raw::decode_file(
            &dir.join(format!("{name}.dng")),
            &pgrf_raw::LevelOverrides::default(),
        )
        .unwrap();
        assert_eq!((f.width, f.height), (384, 256), "{name}");
        assert_eq!(f.cfa, pgrf_raw::Cfa::Rggb, "{name}");
    }
    // `pgrf enhance --model builtin:...` on the demo's noisy DNG, scored by
    // `pgrf metrics`, agrees with the demo's own numbers (the DNG rounds to
    // whole DN, hence 0.05 dB) when it is given the calibrated black level
    // and noise:
    // the file's plus the A7S2's black-level error at ISO 1600 (2.428 DN of
    // its 15,871), rescaled to the file's range.
    let clean = pgrf_raw::decode_file(&dir.join("clean.dng"), &Default::default()).unwrap();
    let black: Vec<String> = clean
        .black
        .iter()
        .map(|&b| (b + 2.428175 * (clean.white as f32 - b) / 15871.0).to_string())
        .collect();
    let black = black.join(",");
    // The noise-aware models are told the noise as the demo tells them, the
    // simulated camera's calibration: the A7S2 at ISO 1600 (K 1.53008 DN/e-,
    // read 6.2992, row 0.9888 DN of its 15,871), on the file's scale.
    let scale = (clean.white as f64 - clean.black[0] as f64) / 15871.0;
    let noise = format!(
        "K={},read={},row={}",
        1.53008 * scale,
        6.2992 * scale,
        0.9888 * scale
    );
    for (model, method) in [("builtin:spc", "spc"), ("builtin:pgrf", "pgrf")] {
        let out = dir.join(format!("enhanced_{method}.dng"));
        let r = pgrf(&[
            "enhance",
            s(&dir.join("noisy_x100.dng")),
            "--model",
            model,
            "--ratio",
            "100",
            "--black",
            &black,
            "--noise",
            &noise,
            "-o",
            s(&out),
            "--quiet",
        ]);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        let m = pgrf(&["metrics", s(&out), s(&dir.join("clean.dng")), "--json"]);
        assert!(m.status.success(), "{}", String::from_utf8_lossy(&m.stderr));
        let m: Value = serde_json::from_slice(&m.stdout).unwrap();
        let (got, want) = (m["psnr"].as_f64().unwrap(), psnr(&v, "x100", method));
        assert!(
            (got - want).abs() < 0.05,
            "{model}: metrics {got} vs demo {want}"
        );
    }
    let e = one_line_error(&pgrf(&[
        "enhance",
        s(&dir.join("noisy_x100.dng")),
        "--model",
        "builtin:nope",
        "--ratio",
        "100",
        "-o",
        s(&dir.join("nope.dng")),
    ]));
    assert!(e.contains("no such built-in model"), "{e}");
    // The picture: 4 columns of half-size frames (192 x 128; the 2x crops
    // are 192 x 128 too), 4 rows with captions.
    let png = image::open(dir.join("demo.png")).unwrap();
    assert_eq!(png.width(), 4 * 192 + 3 * 8);
    assert_eq!(png.height(), 4 * (128 + 30) + 3 * 8);
}

/// Scores of the built-in models on the reduced demo, as MODELS.md records
/// them. Inference and metrics are deterministic; the tolerance covers
/// floating-point summation order in other builds.
const RECORDED: [(&str, &str, f64, f64); 6] = [
    ("x100", "noisy", 25.4575, 0.72156),
    ("x100", "spc", 29.5055, 0.91185),
    ("x100", "pgrf", 29.5095, 0.91224),
    ("x200", "noisy", 21.0664, 0.54725),
    ("x200", "spc", 26.3098, 0.84400),
    ("x200", "pgrf", 26.3149, 0.84522),
];
/// Both models must beat the noisy input by this much at both ratios. The
/// noise-aware ones shipped 2026-11-27 (eighth session) do by 3.8 / 5.1 dB
/// (SPC) and 4.2 / 5.4 dB (PGRF) on the calibrated input, as the blind ones
/// before them did; both are photo-trained, and dead leaves are not what
/// they do best.
const SPC_MARGIN_DB: f64 = 3.0;
const PGRF_MARGIN_DB: f64 = 3.0;

/// Every (ratio, method, PSNR, SSIM) of `table` within 0.02 dB and 5e-4.
fn assert_recorded(v: &Value, table: &[(&str, &str, f64, f64)]) {
    for &(ratio, method, p, q) in table {
        let (gp, gq) = (psnr(v, ratio, method), ssim(v, ratio, method));
        assert!(
            (gp - p).abs() < 0.02 && (gq - q).abs() < 5e-4,
            "{ratio} {method}: {gp:.4} dB / {gq:.5}, MODELS.md records {p} / {q}"
        );
    }
}

#[test]
fn shipped_models_reproduce_the_recorded_scores() {
    let dir = scratch("demo", "recorded");
    let v = run_demo(&dir);
    assert_recorded(&v, &RECORDED);
}

/// Scores of the built-in models on the photograph's 512 x 384 centre
/// window (seed 0), as MODELS.md records them.
const RECORDED_PHOTO: [(&str, &str, f64, f64); 6] = [
    ("x100", "noisy", 30.4841, 0.35378),
    ("x100", "spc", 48.7723, 0.96250),
    ("x100", "pgrf", 48.8886, 0.96558),
    ("x200", "noisy", 24.7378, 0.10862),
    ("x200", "spc", 45.6483, 0.92756),
    ("x200", "pgrf", 45.7809, 0.93218),
];
/// SPC must beat the noisy input on the photograph by this much at both
/// ratios, the issue's +10 dB with room (the noise-aware SPC shipped
/// 2026-11-27 does by 17.0 / 19.2 dB on the calibrated input; the blind
/// third stage before it by 17.3 / 19.6).
const SPC_PHOTO_MARGIN_DB: f64 = 14.0;
/// PGRF's margin on the photograph: the flow correcting the built-in SPC's
/// restoration (built in since 2026-11-29) gains 18.4 / 21.0 dB; the one
/// correcting D2's (built in since 2026-11-28) 17.7 / 20.3 dB; the
/// noise-aware PGRF before it 12.8 / 16.7 dB (the blind fourth stage
/// before it 14.0 / 19.0, its third 12.2 / 17.8, second 9.5 / 14.3; the
/// first gained 5.5 / 8.4 on the uncalibrated input; the dead-leaves model
/// lost 1.1 dB at x100).
const PGRF_PHOTO_MARGIN_DB: f64 = 15.0;

#[test]
fn the_photo_demo_restores_a_window_of_the_built_in_photograph() {
    let dir = scratch("demo", "photo");
    let v = run_scene(&dir, &["--size", PHOTO_SIZE]);
    assert_recorded(&v, &RECORDED_PHOTO);
    for ratio in ["x100", "x200"] {
        let (noisy, spc) = (psnr(&v, ratio, "noisy"), psnr(&v, ratio, "spc"));
        assert!(
            spc >= noisy + SPC_PHOTO_MARGIN_DB,
            "{ratio}: SPC {spc:.2}, noisy {noisy:.2}"
        );
        let pgrf = psnr(&v, ratio, "pgrf");
        assert!(
            pgrf >= noisy + PGRF_PHOTO_MARGIN_DB,
            "{ratio}: PGRF {pgrf:.2}, noisy {noisy:.2}"
        );
    }
    // clean.dng is the photograph's centre window, sample for sample: the
    // 1734 x 1156 frame less 512 x 384 leaves (1222, 772) around it, halved
    // to whole CFA cells: columns 610.., rows 386...
    let asset = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/canon550d_colorchart.dng");
    let levels = pgrf_raw::LevelOverrides::default();
    let photo = pgrf_raw::decode_file(&asset, &levels).unwrap();
    let clean = pgrf_raw::decode_file(&dir.join("clean.dng"), &levels).unwrap();
    assert_eq!(
        (clean.width, clean.height, clean.cfa),
        (512, 384, photo.cfa)
    );
    assert_eq!((clean.black, clean.white), (photo.black, photo.white));
    for (r, c) in [(0, 0), (1, 1), (200, 301), (383, 511)] {
        assert_eq!(clean.at(r, c), photo.at(386 + r, 610 + c), "({r}, {c})");
    }
    let dark = pgrf_raw::decode_file(&dir.join("noisy_x200.dng"), &levels).unwrap();
    assert_eq!(dark.iso, Some(1600));
    assert!(
        (dark.exposure_s.unwrap() - 1.0 / 200.0).abs() < 1e-9,
        "{:?}",
        dark.exposure_s
    );
}

#[test]
fn bad_demo_arguments_are_one_line_errors() {
    let dir = scratch("demo", "bad");
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models");
    // The flow model where the SPC denoiser belongs.
    let e = one_line_error(&pgrf(&[
        "demo",
        "-o",
        s(&dir.join("a")),
        "--spc",
        s(&models.join("pgrf.safetensors")),
    ]));
    assert!(e.contains("not the SPC model"), "{e}");
    let e = one_line_error(&pgrf(&["demo", "-o", s(&dir.join("b")), "--size", "100x7"]));
    assert!(e.contains("--size 100x7"), "{e}");
    let e = one_line_error(&pgrf(&[
        "demo",
        "-o",
        s(&dir.join("b")),
        "--size",
        "2000x1000",
    ]));
    assert!(e.contains("larger than"), "{e}");
    let e = one_line_error(&pgrf(&[
        "demo",
        "-o",
        s(&dir.join("b")),
        "--scene",
        "procedural",
        "--photo",
        s(&models.join("spc.toml")),
    ]));
    assert!(e.contains("--photo goes with --scene photo"), "{e}");
    let e = one_line_error(&pgrf(&[
        "demo",
        "-o",
        s(&dir.join("b")),
        "--photo",
        s(&models.join("spc.toml")),
    ]));
    assert!(e.contains("--photo"), "{e}");
    let e = one_line_error(&pgrf(&["demo", "-o", s(&dir.join("missing/out"))]));
    assert!(e.contains("does not exist"), "{e}");
    let e = one_line_error(&pgrf(&[
        "demo",
        "-o",
        s(&dir.join("c")),
        "--pgrf",
        s(&dir.join("nothing.safetensors")),
    ]));
    assert!(e.contains("--pgrf"), "{e}");
    // Nothing was written for any of them.
    for d in ["a", "b", "c"] {
        let p = dir.join(d);
        assert!(
            !p.exists() || std::fs::read_dir(&p).unwrap().next().is_none(),
            "{}",
            p.display()
        );
    }
}

/// A noise-aware SPC runs in the demo, on a window too small for a blind
/// noise estimate: it is told each capture's noise as the simulated camera's
/// calibration states it; a residual model trained two steps stays within
/// 1 dB of the noisy input it starts from.
#[test]
fn a_noise_aware_model_runs_in_the_demo() {
    let dir = scratch("demo", "noise-aware");
    let m = dir.join("aware.safetensors");
    common::noise_aware_model(&m);
    let out = dir.join("out");
    let v = run_scene(
        &out,
        &["--scene", "procedural", "--size", "64x64", "--spc", s(&m)],
    );
    for ratio in ["x100", "x200"] {
        let (spc, noisy) = (psnr(&v, ratio, "spc"), psnr(&v, ratio, "noisy"));
        assert!((spc - noisy).abs() < 1.0, "{ratio}: {spc} vs {noisy}");
    }
}
