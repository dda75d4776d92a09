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

/// An empty folder for one test of `suite`, unique to this process.
pub fn scratch(suite: &str, name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pgrf-{suite}-test-{}-{name}", std::process::id()));
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
