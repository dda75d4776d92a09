//! The `pgrf-bench` binary's command line: every benchmark has `--help`,
//! usage errors exit 2, and failures are one `pgrf-bench: error: ...` line
//! with exit code 1, as `pgrf`'s are.

use std::process::{Command, Output};

fn bench(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pgrf-bench"))
        .args(args)
        .output()
        .expect("run pgrf-bench")
}

#[test]
fn every_benchmark_has_help() {
    for cmd in [
        vec!["--help"],
        vec!["decode", "--help"],
        vec!["synth", "--help"],
        vec!["stack", "--help"],
        vec!["train", "--help"],
        vec!["enhance", "--help"],
        vec!["ssim", "--help"],
    ] {
        let out = bench(&cmd);
        assert!(out.status.success(), "{cmd:?}");
        assert!(
            String::from_utf8_lossy(&out.stdout).contains("Usage"),
            "{cmd:?}"
        );
    }
    // Unknown flags and missing arguments are usage errors (exit 2).
    assert_eq!(
        bench(&["decode", "--frobnicate", "x"]).status.code(),
        Some(2)
    );
    assert_eq!(bench(&["decode"]).status.code(), Some(2));
}

#[test]
fn failures_are_one_error_line() {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("pgrf-bench-cli");
    std::fs::create_dir_all(&dir).unwrap();
    let missing = dir.join("missing.dng");
    for args in [
        vec!["decode", missing.to_str().unwrap(), "--iters", "1"],
        vec!["decode", missing.to_str().unwrap(), "--iters", "0"],
        vec!["train", "--size", "40"],
        vec!["ssim", "--iters", "0"],
    ] {
        let out = bench(&args);
        assert_eq!(out.status.code(), Some(1), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(err.starts_with("pgrf-bench: error: "), "{args:?}: {err}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn enhance_dry_run_prints_the_plan() {
    let out = bench(&[
        "enhance",
        "--frame",
        "64x96",
        "--tile",
        "64",
        "--overlap",
        "16",
        "--dry-run",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let plan: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON line");
    assert_eq!(plan["frame"], serde_json::json!([4, 64, 96]));
    assert_eq!(plan["tile"], 64);
    assert_eq!(plan["nfe"], 1);
    assert!(plan["tiles"].as_u64().unwrap() >= 2);
}

/// The frame's clean mean (the module docs' formula without the noise).
fn clean_mean(h: usize, w: usize) -> f64 {
    let mut sum = 0.0;
    for c in 0..4 {
        for i in 0..h {
            for j in 0..w {
                let tri = ((i + 2 * j + 16 * c) % 512).abs_diff(256);
                sum += 0.8 * (4 * tri + (7 * i + 3 * j) % 41) as f64 / 1100.0;
            }
        }
    }
    sum / (4 * h * w) as f64
}

/// Both built-ins are noise-conditioned: the bench gives them the frame's
/// noise level (it refused to run them before), and what they return is a
/// restoration of the frame, not noise: its mean is the clean frame's
/// (0.3241) within 0.01 (measured 0.3211 for both).
#[test]
fn enhance_times_the_built_in_models() {
    let models = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models");
    for (name, nfe) in [("spc", 1), ("pgrf", 2)] {
        let model = models.join(format!("{name}.safetensors"));
        let out = bench(&[
            "enhance",
            "--model",
            model.to_str().unwrap(),
            "--frame",
            "64x96",
            "--iters",
            "1",
            "--warmup",
            "0",
            "--json",
        ]);
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON line");
        assert_eq!(report["nfe"], nfe, "{name}");
        let mean = report["output_mean"].as_f64().unwrap();
        let clean = clean_mean(64, 96);
        assert!(
            (mean - clean).abs() < 0.01,
            "{name}: mean {mean}, clean {clean}"
        );
    }
}
