//! What every CLI test file needs: run the binary, a fresh scratch folder per
//! test, paths as arguments, and the one-line-error contract.

// Each test file is its own crate and uses only some of these.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn pgrf(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pgrf"))
        .args(args)
        .output()
        .expect("run pgrf")
}

/// `pgrf args`, which must succeed (else the test fails with its stderr).
pub fn pgrf_ok(args: &[&str]) -> Output {
    let out = pgrf(args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// An empty folder for one test of `suite`, under cargo's target/tmp: a
/// rerun empties the same folder, so runs do not pile up in the system's
/// temporary folder (they once filled the disk).
pub fn scratch(suite: &str, name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("pgrf-{suite}-test-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The run failed with exit code 1 and exactly one non-empty line on
/// stderr, which is returned.
pub fn one_line_error(out: &Output) -> String {
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert_eq!(out.status.code(), Some(1), "stderr: {err}");
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "expected one line, got: {err}");
    err
}

/// A tiny network with seeded weights saved as a weight file in `dir`
/// (`spc.safetensors` or `flow.safetensors`): for tests of the plumbing,
/// not of denoising.
pub fn tiny_model(dir: &Path, flow: bool, t2: Option<f32>, seed: u64) -> PathBuf {
    use pgrf_nn::backend::Cpu;
    use pgrf_nn::weights::{NoiseSource, WeightMeta};
    use pgrf_nn::Architecture;
    use pgrf_nn::{SidUnetConfig, Sr3Config};
    let device = Default::default();
    let arch = if flow {
        Architecture::Sr3(
            Sr3Config::new()
                .with_inner_channels(8)
                .with_channel_mults(vec![1, 2])
                .with_res_blocks(1)
                .with_attn_levels(vec![])
                .with_norm_groups(4),
        )
    } else {
        Architecture::SidUnet(SidUnetConfig::new().with_width(4))
    };
    let net = arch.init_seeded::<Cpu>(&device, seed).unwrap();
    let mut meta = WeightMeta::new(
        arch,
        NoiseSource {
            profile: Some("sony-a7s2".into()),
            calibration: None,
            model: pgrf_noise::ModelKind::Pgrf,
            iso: Some(1600),
            iso_range: None,
            ratio: [100.0, 300.0],
            calibrated_dark_level: false,
        },
    );
    meta.t2 = t2;
    let path = dir.join(if flow {
        "flow.safetensors"
    } else {
        "spc.safetensors"
    });
    net.save(&path, &meta).unwrap();
    path
}

/// `pgrf chart -o path --width w --height h`, required to succeed.
pub fn chart(path: &Path, width: u32, height: u32) {
    let (w, h) = (width.to_string(), height.to_string());
    let out = pgrf(&["chart", "-o", s(path), "--width", &w, "--height", &h]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A tiny sigma-map conditioned SPC (`pgrf train spc --conditioning
/// sigma-map`, two steps on procedural scenes) written to `path`: for
/// tests of how noise-aware models are told their input's noise.
pub fn noise_aware_model(path: &Path) {
    let r = pgrf(&[
        "train",
        "spc",
        "--data",
        "procedural",
        "--steps",
        "2",
        "--batch",
        "1",
        "--patch",
        "32",
        "--width",
        "4",
        "--residual",
        "--conditioning",
        "sigma-map",
        "-o",
        s(path),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
}

/// A calibrated virtual sensor (`size` pixels, FITS, seed 1, darks at 0.02 and
/// 0.05 s, -10 °C) and its lights (the 0.04 s flats of a second run, seed
/// 9): what the reference script makes (`fits` false: DNG frames).
/// Returns (vs, lights).
pub fn sensor(dir: &Path, size: (u32, u32), mono: bool, fits: bool) -> (PathBuf, Vec<PathBuf>) {
    let (vs, src, lights) = (dir.join("vs"), dir.join("src"), dir.join("lights"));
    let (width, height) = (size.0.to_string(), size.1.to_string());
    let mut common = vec![
        "--width",
        &width,
        "--height",
        &height,
        "--temperature",
        "-10",
    ];
    if fits {
        common.push("--fits");
    }
    if mono {
        common.push("--mono");
    }
    let run = |args: &[&str]| {
        pgrf_ok(args);
    };
    let mut a = vec!["simulate-sensor"];
    a.extend(&common);
    a.extend([
        "--frames",
        "8",
        "--dark-exposures",
        "0.02,0.05",
        "-o",
        s(&vs),
    ]);
    run(&a);
    let (bias, dark, flat) = (vs.join("bias"), vs.join("dark"), vs.join("flat"));
    let (masters, calib) = (vs.join("masters"), vs.join("calib.safetensors"));
    run(&[
        "calibrate",
        "--bias",
        s(&bias),
        "--dark",
        s(&dark),
        "--flat",
        s(&flat),
        "--masters",
        s(&masters),
        "-o",
        s(&calib),
    ]);
    let mut a = vec!["simulate-sensor"];
    a.extend(&common);
    a.extend([
        "--frames",
        "2",
        "--stacks",
        "flat",
        "--seed",
        "9",
        "-o",
        s(&src),
    ]);
    run(&a);
    std::fs::create_dir_all(&lights).unwrap();
    let mut files = Vec::new();
    for i in 0..2 {
        let ext = if fits { "fits" } else { "dng" };
        let name = format!("flat_8000e_{i:04}.{ext}");
        let to = lights.join(&name);
        std::fs::copy(src.join("flat").join(&name), &to).unwrap();
        files.push(to);
    }
    (vs, files)
}

/// `pgrf reduce LIGHTS --masters --calib -o OUT` with the sensor's masters
/// and calibration ([`sensor`]).
pub fn reduce(vs: &Path, lights: &[PathBuf], out: &Path) -> std::process::Output {
    let mut args = vec!["reduce".to_string()];
    args.extend(lights.iter().map(|l| s(l).to_string()));
    for a in [
        "--masters",
        s(&vs.join("masters")),
        "--calib",
        s(&vs.join("calib.safetensors")),
        "-o",
        s(out),
    ] {
        args.push(a.to_string());
    }
    let args: Vec<&str> = args.iter().map(|a| a.as_str()).collect();
    pgrf(&args)
}
