//! Flags at absurd or edge values (issue 37, finding 6): a negative Euler
//! step count is refused rather than read as positive, every u64 seed is a
//! seed, exposure ratios lie in 1..10000, an error's cause is said once,
//! `enhance -o` names a DNG or a folder, and `make-dataset` refuses a
//! benchmark the disk cannot hold, each in one line before any work.

mod common;
use common::{one_line_error, pgrf, s, scratch};

use serde_json::Value;
use std::path::Path;

fn chart(dir: &Path) -> std::path::PathBuf {
    let c = dir.join("c.dng");
    common::chart(&c, 128, 96);
    c
}

fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn a_negative_euler_count_is_refused() {
    let d = scratch("bounds", "euler");
    let c = chart(&d);
    let out = d.join("e.dng");
    for bad in ["euler:-5", "euler--5"] {
        let r = pgrf(&[
            "enhance",
            s(&c),
            "--model",
            "builtin:pgrf",
            "--sampler",
            bad,
            "--ratio",
            "20",
            "-o",
            s(&out),
        ]);
        let err = String::from_utf8_lossy(&r.stderr);
        // A usage error: clap's exit code 2, its first line pgrf's.
        assert_eq!(r.status.code(), Some(2), "{err}");
        let first = err.lines().next().unwrap();
        assert!(
            first.starts_with("pgrf: error: ")
                && first.contains(bad)
                && first.contains("from 1 to 10000"),
            "{first}"
        );
        assert!(!out.exists());
    }
}

#[test]
fn every_u64_seed_trains_and_round_trips_through_a_config_file() {
    let d = scratch("bounds", "seed");
    let big = "9223372036854775808"; // 2^63: above TOML's integers
    let out = d.join("m.safetensors");
    let base = [
        "train",
        "denoiser",
        "--steps",
        "1",
        "--width",
        "4",
        "--patch",
        "32",
        "--val-pairs",
        "1",
        "--data",
        "procedural",
        "--iso",
        "1600",
        "--quiet",
        "--json",
    ];
    let mut args = base.to_vec();
    args.extend_from_slice(&["--seed", big, "-o", s(&out)]);
    let r = pgrf(&args);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let b = std::fs::read(&out).unwrap();
    let n = u64::from_le_bytes(b[..8].try_into().unwrap()) as usize;
    let header: Value = serde_json::from_slice(&b[8..8 + n]).unwrap();
    let rec: Value =
        serde_json::from_str(header["__metadata__"]["pgrf"].as_str().unwrap()).unwrap();
    assert_eq!(rec["training"]["seed"].as_u64(), Some(1u64 << 63));

    // --print-config writes it as a string; the file trains the same seed.
    let mut args = base.to_vec();
    args.extend_from_slice(&["--seed", big, "-o", s(&out), "--print-config"]);
    let r = pgrf(&args);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let toml = String::from_utf8_lossy(&r.stdout).to_string();
    assert!(toml.contains(&format!("seed = \"{big}\"")), "{toml}");
    let cfg = d.join("t.toml");
    std::fs::write(&cfg, &toml).unwrap();
    let r = pgrf(&["train", "denoiser", "--config", s(&cfg), "--print-config"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert_eq!(String::from_utf8_lossy(&r.stdout), toml);
    // u64::MAX too; one past it is clap's usage error.
    let mut args = base.to_vec();
    args.extend_from_slice(&[
        "--seed",
        "18446744073709551615",
        "-o",
        s(&out),
        "--print-config",
    ]);
    assert!(pgrf(&args).status.success());
    let mut args = base.to_vec();
    args.extend_from_slice(&["--seed", "18446744073709551616", "-o", s(&out)]);
    assert_eq!(pgrf(&args).status.code(), Some(2));
}

#[test]
fn exposure_ratios_outside_one_to_ten_thousand_are_refused() {
    let d = scratch("bounds", "ratio");
    let c = chart(&d);
    let out = d.join("o.dng");
    let before = files_in(&d);
    for ratio in ["1e30", "1e-30", "0.5", "10001"] {
        for cmd in ["enhance", "synth"] {
            let mut args = vec![cmd, s(&c), "--ratio", ratio, "-o", s(&out)];
            match cmd {
                "enhance" => args.extend_from_slice(&["--model", "builtin:spc"]),
                _ => args.extend_from_slice(&["--profile", "sony-a7s2"]),
            }
            let e = one_line_error(&pgrf(&args));
            assert!(
                e.contains(&format!(
                    "--ratio {ratio}: the exposure ratio must be from 1 to 10000"
                )),
                "{cmd} {ratio}: {e}"
            );
        }
        let e = one_line_error(&pgrf(&[
            "eval",
            "--protocol",
            "synthetic",
            "--root",
            s(&c),
            "--model",
            "builtin:spc",
            "--iso",
            "1600",
            "--ratio",
            ratio,
        ]));
        assert!(e.contains("from 1 to 10000"), "eval {ratio}: {e}");
        // The sampling search's pairs and a training run's range too.
        let flow = d.join("flow.safetensors");
        let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/pgrf.safetensors");
        std::fs::copy(&shipped, &flow).unwrap();
        let e = one_line_error(&pgrf(&[
            "search",
            "--model",
            s(&flow),
            "--procedural",
            "2",
            "--ratio",
            ratio,
        ]));
        assert!(
            e.contains("--ratio") && e.contains("from 1 to 10000"),
            "search {ratio}: {e}"
        );
        let model = d.join("m.safetensors");
        for flag in ["--ratio-min", "--ratio-max"] {
            let e = one_line_error(&pgrf(&["train", "spc", flag, ratio, "-o", s(&model)]));
            assert!(
                e.contains(flag) && e.contains("from 1 to 10000"),
                "train {flag} {ratio}: {e}"
            );
        }
        std::fs::remove_file(&flow).unwrap();
    }
    // A target exposure that makes such a ratio (the chart records 1/60 s).
    let e = one_line_error(&pgrf(&[
        "enhance",
        s(&c),
        "--model",
        "builtin:spc",
        "--target-exposure",
        "1e30",
        "-o",
        s(&out),
    ]));
    assert!(e.contains("is a ratio of 6e31"), "{e}");
    assert_eq!(files_in(&d), before, "something was written");
    // The ends of the range are taken: x10000 divides the exposure by 10000.
    let r = pgrf(&[
        "synth",
        s(&c),
        "--profile",
        "sony-a7s2",
        "--ratio",
        "10000",
        "-o",
        s(&out),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let info = pgrf(&["info", s(&out), "--json"]);
    let v: Value = serde_json::from_slice(&info.stdout).unwrap();
    let t = v["exposure_s"].as_f64().unwrap();
    assert!((t - 1.0 / 60.0 / 10000.0).abs() < 1e-9, "{t}");
}

#[test]
fn an_errors_cause_is_said_once() {
    let d = scratch("bounds", "once");
    let c = chart(&d);
    let missing = d.join("nodir").join("x.dng");
    for cmd in ["convert", "preview"] {
        let out = missing.with_extension(if cmd == "preview" { "png" } else { "dng" });
        let e = one_line_error(&pgrf(&[cmd, s(&c), "-o", s(&out)]));
        assert_eq!(e.matches("does not exist").count(), 1, "{e}");
    }
}

#[test]
fn enhance_output_names_a_dng_or_a_folder() {
    let d = scratch("bounds", "enhance_o");
    let c = chart(&d);
    let model = d.join("model.safetensors");
    std::fs::write(&model, b"not a folder").unwrap();
    for (out, says) in [
        (d.join("new.safetensors"), "has the extension .safetensors"),
        (model.clone(), "is an existing file, not a folder"),
    ] {
        let e = one_line_error(&pgrf(&[
            "enhance",
            s(&c),
            "--model",
            "builtin:spc",
            "--ratio",
            "20",
            "-o",
            s(&out),
        ]));
        assert!(
            e.contains(says) && e.contains("enhance writes DNG files"),
            "{e}"
        );
    }
    assert!(!d.join("new.safetensors").exists());
    assert_eq!(std::fs::read(&model).unwrap(), b"not a folder");
    // A new folder without an extension is made, as before (the
    // noise-aware SPC told the noise: the small chart has too few flat
    // blocks for a blind estimate).
    let r = pgrf(&[
        "enhance",
        s(&c),
        "--model",
        "builtin:spc",
        "--ratio",
        "20",
        "--noise",
        "K=1,read=4",
        "-o",
        s(&d.join("outdir")),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert!(d.join("outdir/c.dng").is_file());
}

#[test]
fn make_dataset_refuses_what_the_disk_cannot_hold() {
    let d = scratch("bounds", "dataset");
    let out = d.join("ds");
    let e = one_line_error(&pgrf(&[
        "make-dataset",
        "--layout",
        "eld",
        "-o",
        s(&out),
        "--scenes",
        "1000000000",
    ]));
    assert!(
        e.contains("--scenes 1000000000 of 256x256 frames (16 per scene) would write 17000000000 files, about 1.3 PB")
            && e.contains("give fewer --scenes"),
        "{e}"
    );
    assert!(!out.exists());
    let r = pgrf(&[
        "make-dataset",
        "--layout",
        "sid",
        "-o",
        s(&out),
        "--scenes",
        "1",
        "--size",
        "64x64",
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
}
