//! `pgrf train` as scripts use it: flags and TOML config, the JSON summary,
//! weight files with their record, resume, and one-line errors.

mod common;
use common::{one_line_error, pgrf, s};

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn scratch(name: &str) -> PathBuf {
    common::scratch("train", name)
}

fn summary(out: &Output) -> Value {
    assert!(
        out.status.success(),
        "pgrf failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(text.lines().last().expect("a JSON line")).expect("JSON summary")
}

/// Small settings shared by the tests: seconds on two cores.
const SMALL: &[&str] = &[
    "--data",
    "procedural",
    "--patch",
    "32",
    "--batch",
    "2",
    "--seed",
    "1",
    "--val-pairs",
    "2",
    "--val-every",
    "4",
    "--iso",
    "1600",
    "--quiet",
    "--json",
];

/// The JSON record a weight file carries in its safetensors header.
fn record(p: &Path) -> Value {
    let b = std::fs::read(p).unwrap();
    let n = u64::from_le_bytes(b[..8].try_into().unwrap()) as usize;
    let header: Value = serde_json::from_slice(&b[8..8 + n]).unwrap();
    serde_json::from_str(header["__metadata__"]["pgrf"].as_str().unwrap()).unwrap()
}

#[test]
fn denoiser_trains_resumes_and_writes_a_described_weight_file() {
    let d = scratch("denoiser");
    let out = d.join("m.safetensors");
    let mut args = vec![
        "train",
        "denoiser",
        "--steps",
        "6",
        "--width",
        "4",
        "-o",
        s(&out),
        "--schedule",
        "constant",
    ];
    args.extend_from_slice(SMALL);
    let full = summary(&pgrf(&args));
    assert_eq!(full["steps"], 6);
    assert!(full["final_loss"].as_f64().unwrap() > 0.0);
    assert!(full["val_psnr"].as_f64().unwrap().is_finite());
    assert!(full["images_per_s"].as_f64().unwrap() > 0.0);
    let log = std::fs::read_to_string(out.with_extension("log.csv")).unwrap();
    assert!(
        log.starts_with("step,loss,lr,images_per_s,val_psnr,seconds\n"),
        "{log}"
    );
    assert!(log.lines().last().unwrap().starts_with("6,"), "{log}");

    // The record says what the file is.
    let meta = record(&out);
    assert_eq!(meta["format"], "pgrf-weights");
    assert_eq!(meta["arch"], "sid-unet");
    assert_eq!(meta["config"]["width"], 4);
    assert_eq!(meta["noise"]["profile"], "sony-a7s2");
    assert_eq!(meta["training"]["steps"], 6);

    // 3 steps, then resume to 6: the same weights bit for bit (the data
    // stream is a function of the step, the optimiser state is checkpointed).
    // The schedule is relative to --steps, so both runs use a constant rate.
    let half = d.join("h.safetensors");
    let mut a = vec![
        "train",
        "denoiser",
        "--steps",
        "3",
        "--width",
        "4",
        "-o",
        s(&half),
        "--schedule",
        "constant",
    ];
    a.extend_from_slice(SMALL);
    assert_eq!(summary(&pgrf(&a))["steps"], 3);
    let mut b = vec![
        "train",
        "denoiser",
        "--steps",
        "6",
        "--width",
        "4",
        "-o",
        s(&half),
        "--resume",
        "--schedule",
        "constant",
    ];
    b.extend_from_slice(SMALL);
    let resumed = summary(&pgrf(&b));
    assert_eq!(resumed["steps_this_run"], 3);
    assert_eq!(resumed["final_loss"], full["final_loss"]);
    let tensors = |p: &Path| {
        let b = std::fs::read(p).unwrap();
        let n = u64::from_le_bytes(b[..8].try_into().unwrap()) as usize;
        b[8 + n..].to_vec()
    };
    assert!(tensors(&half) == tensors(&out), "resumed weights differ");

    // Resuming into another architecture is refused in one line.
    let mut c = vec![
        "train",
        "denoiser",
        "--steps",
        "8",
        "--width",
        "8",
        "-o",
        s(&half),
        "--resume",
    ];
    c.extend_from_slice(SMALL);
    let e = one_line_error(&pgrf(&c));
    assert!(e.contains("another network"), "{e}");

    // Fine-tuning: --init starts from a weight file. With no steps the
    // result holds exactly its weights; the record names the file and adds
    // up the steps behind it, through a chain of fine-tunings.
    let fine_tune = |steps: &str, out: &Path, init: &Path| {
        let mut a = vec!["train", "denoiser", "--steps", steps, "--width", "4"];
        a.extend_from_slice(&["-o", s(out), "--init", s(init)]);
        a.extend_from_slice(SMALL);
        summary(&pgrf(&a))
    };
    let started_from = |p: &Path| {
        let from = &record(p)["training"]["started_from"];
        (
            from["file"].as_str().map(String::from),
            from["steps"].as_u64(),
        )
    };
    let tuned = d.join("t.safetensors");
    assert_eq!(fine_tune("0", &tuned, &out)["steps"], 0);
    assert!(
        tensors(&tuned) == tensors(&out),
        "--init did not start from the file's weights"
    );
    assert_eq!(
        started_from(&tuned),
        (Some("m.safetensors".into()), Some(6))
    );
    let again = d.join("t2.safetensors");
    assert_eq!(fine_tune("2", &again, &half)["steps"], 2);
    assert!(
        tensors(&again) != tensors(&half),
        "two steps changed nothing"
    );
    let chained = d.join("t3.safetensors");
    fine_tune("0", &chained, &again);
    assert_eq!(
        started_from(&chained),
        (Some("t2.safetensors".into()), Some(8))
    );
    // A wider network starts from the narrower one's weights (issue 51,
    // lever 4) and says so.
    let wide = d.join("wide.safetensors");
    let mut w = vec!["train", "denoiser", "--steps", "1", "--width", "8"];
    w.extend_from_slice(&["-o", s(&wide), "--init", s(&out)]);
    // Not --quiet: the note is what is checked.
    w.extend(SMALL.iter().filter(|a| **a != "--quiet"));
    let r = pgrf(&w);
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{err}");
    assert!(
        err.contains("width-4 weights in the old channels of width 8"),
        "{err}"
    );
    // A narrower width, or no such file: one line, nothing written.
    for (init, says) in [
        (s(&out), "holds SPC denoiser (SID U-Net, width 4)"),
        ("nope.safetensors", "nope.safetensors"),
    ] {
        let bad = d.join("bad.safetensors");
        let mut b = vec!["train", "denoiser", "--steps", "1", "--width", "2"];
        b.extend_from_slice(&["-o", s(&bad), "--init", init]);
        b.extend_from_slice(SMALL);
        let e = one_line_error(&pgrf(&b));
        assert!(e.contains(says), "{e}");
        assert!(!bad.exists());
    }
}

#[test]
fn flow_trains_from_a_toml_config_that_flags_override() {
    let d = scratch("flow");
    let out = d.join("f.safetensors");
    let cfg = d.join("flow.toml");
    std::fs::write(
        &cfg,
        format!(
            "data = \"procedural\"\nsteps = 50\ninner_channels = 8\nchannel_mults = [1, 2]\n\
             attn_levels = [1]\nres_blocks = 1\npatch = 16\nlr = 1e-3\nschedule = \"constant\"\n\
             log = \"{}\"\n",
            s(&d.join("log.jsonl"))
        ),
    )
    .unwrap();
    let args = [
        "train",
        "flow",
        "--config",
        s(&cfg),
        "--steps",
        "3",
        "--val-pairs",
        "1",
        "-o",
        s(&out),
        "--quiet",
        "--json",
    ];
    let j = summary(&pgrf(&args));
    assert_eq!(j["steps"], 3, "the flag overrides the file's 50");
    assert_eq!(j["method"], "pgrf");
    let log = std::fs::read_to_string(d.join("log.jsonl")).unwrap();
    let last: Value = serde_json::from_str(log.lines().last().unwrap()).unwrap();
    assert_eq!(last["step"], 3);
    assert!(last["val_psnr"].as_f64().is_some());
    let meta = record(&out);
    assert_eq!(meta["arch"], "sr3");
    assert_eq!(meta["config"]["channel_mults"], serde_json::json!([1, 2]));
    assert_eq!(
        meta["config"]["norm_groups"], 8,
        "largest group count dividing 8 and 16"
    );
    assert!(meta["t2"].is_null());
}

/// A mix of cameras' noise: the header names the shares, the weight file
/// records the mix and the ISO range, and the sampling search rebuilds its
/// pairs from that record.
#[test]
fn a_profile_mix_trains_is_recorded_and_searches() {
    let d = scratch("mix");
    let out = d.join("mix.safetensors");
    let r = pgrf(&[
        "train",
        "flow",
        "--data",
        "procedural",
        "--profile",
        "sony-a7s2@3,nikon-d850@1",
        "--iso-range",
        "800,3200",
        "--steps",
        "2",
        "--patch",
        "16",
        "--batch",
        "2",
        "--inner-channels",
        "8",
        "--channel-mults",
        "1,2",
        "--attn-levels",
        "1",
        "--val-pairs",
        "1",
        "--calibrated-dark-level",
        "--time-max",
        "0.5",
        "--ratio-draw",
        "log",
        "-o",
        s(&out),
    ]);
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{err}");
    assert!(
        err.contains("noise pgrf from sony-a7s2 (75%) + nikon-d850 (25%) (dark level calibrated)"),
        "{err}"
    );
    assert!(err.contains("(Eld), times t ~ U(0, 0.5),"), "{err}");
    let meta = pgrf_nn::weights::read_meta(&out).unwrap();
    assert!(meta.noise.calibrated_dark_level);
    let t = meta.training.as_ref().unwrap();
    assert_eq!(t.config.as_ref().unwrap().time_max, 0.5);
    assert_eq!(
        meta.noise.profile.as_deref(),
        Some("sony-a7s2@3,nikon-d850@1")
    );
    assert_eq!(meta.noise.iso_range, Some([800, 3200]));
    let r = pgrf(&[
        "search",
        "--model",
        s(&out),
        "--procedural",
        "2",
        "--patch",
        "16",
        "--step",
        "0.5",
        "--dry-run",
    ]);
    let text = String::from_utf8_lossy(&r.stdout);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert!(
        text.contains("noise: sony-a7s2 (75%) + nikon-d850 (25%) pgrf, ISO 800..3200"),
        "{text}"
    );
    // The pairs' ratios are drawn as the training drew them.
    assert!(text.contains(", ratio logU(1, 300), seed "), "{text}");
    // Photos validate too, unprocessed as the record's configuration says;
    // the broken one is a note, not a failure.
    let photos = photo_folder(&d);
    let r = pgrf(&[
        "search",
        "--model",
        s(&out),
        "--val",
        s(&photos),
        "--pairs",
        "2",
        "--patch",
        "16",
        "--step",
        "0.5",
        "--dry-run",
    ]);
    let (text, err) = (
        String::from_utf8_lossy(&r.stdout),
        String::from_utf8_lossy(&r.stderr),
    );
    assert!(r.status.success(), "{err}");
    assert!(
        text.contains("2 crops of 4 photos unprocessed into the camera's RAW space (2x downscale)"),
        "{text}"
    );
    assert!(
        err.contains("note: --val: ") && err.contains("broken.jpg"),
        "{err}"
    );
    // Enhancing without --calib with a model of calibrated captures: a note.
    let chart = d.join("chart.dng");
    common::chart(&chart, 64, 64);
    let r = pgrf(&[
        "enhance",
        s(&chart),
        "--model",
        s(&out),
        "--ratio",
        "100",
        "-o",
        s(&d.join("e.dng")),
    ]);
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{err}");
    assert!(
        err.contains("learned calibrated captures (dark level subtracted); without --calib"),
        "{err}"
    );
}

#[test]
fn bad_settings_are_one_line_errors_and_write_nothing() {
    let d = scratch("bad");
    let out = d.join("x.safetensors");
    let cfg = d.join("bad.toml");
    std::fs::write(&cfg, "stepz = 3\n").unwrap();
    let none = d.join("none");
    let empty = d.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    // A data folder holding a file that is no image (outputs may not go
    // into it: pgrf_core::paths::Io).
    let mixed = d.join("mixed");
    std::fs::create_dir_all(&mixed).unwrap();
    std::fs::write(mixed.join("bad.toml"), "stepz = 3\n").unwrap();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["train", "denoiser", "--config", s(&cfg), "-o", s(&out)],
            "stepz",
        ),
        (
            vec!["train", "denoiser", "--data", s(&none), "-o", s(&out)],
            "none",
        ),
        (
            vec!["train", "denoiser", "--data", s(&empty), "-o", s(&out)],
            "no files",
        ),
        (
            vec!["train", "denoiser", "--data", s(&mixed), "-o", s(&out)],
            "bad.toml",
        ),
        (
            vec!["train", "denoiser", "--data", s(&d), "-o", s(&out)],
            "is inside the input folder",
        ),
        (
            vec!["train", "flow", "--attn-levels", "7", "-o", s(&out)],
            "attn-levels",
        ),
        (
            vec![
                "train",
                "flow",
                "--inner-channels",
                "6",
                "--norm-groups",
                "4",
                "-o",
                s(&out),
            ],
            "norm_groups",
        ),
        (
            vec!["train", "denoiser", "--ratio-min", "0", "-o", s(&out)],
            "ratio",
        ),
        (
            vec![
                "train",
                "denoiser",
                "--steps",
                "1",
                "-o",
                "/no/such/dir/m.safetensors",
            ],
            "does not exist",
        ),
        (
            vec!["train", "denoiser", "--resume", "-o", s(&out)],
            "no checkpoint",
        ),
        (
            vec![
                "train",
                "denoiser",
                "--profile",
                "no-such-camera",
                "-o",
                s(&out),
            ],
            "no-such-camera",
        ),
        (
            vec![
                "train",
                "spc",
                "--profile",
                "sony-a7s2@0,nikon-d850",
                "-o",
                s(&out),
            ],
            "positive number",
        ),
        (
            vec![
                "train",
                "flow",
                "--channel-mults",
                "1,0",
                "--attn-levels",
                "0",
                "-o",
                s(&out),
            ],
            "at least 1",
        ),
        (
            vec!["train", "flow", "--inner-channels", "3", "-o", s(&out)],
            "must be even",
        ),
        (
            vec!["train", "spc", "--clip-grad", "0", "-o", s(&out)],
            "--clip-grad",
        ),
        (
            vec!["train", "spc", "--clip-grad", "NaN", "-o", s(&out)],
            "--clip-grad",
        ),
        (
            vec!["train", "spc", "--photo-wb-spread", "0.5", "-o", s(&out)],
            "--photo-wb-spread must be between 1",
        ),
        (
            vec!["train", "flow", "--time-max", "0", "-o", s(&out)],
            "--time-max must be in (0, 1]",
        ),
        (
            vec!["train", "flow", "--time-max", "1.5", "-o", s(&out)],
            "--time-max must be in (0, 1]",
        ),
        (
            vec!["train", "flow", "--time-max", "NaN", "-o", s(&out)],
            "--time-max must be in (0, 1]",
        ),
        (
            vec!["train", "spc", "--time-max", "0.5", "-o", s(&out)],
            "the SPC denoiser has none",
        ),
        (
            vec![
                "train",
                "spc",
                "--profile",
                "sony-a7s2,nikon-d850",
                "--calib",
                s(&cfg),
                "-o",
                s(&out),
            ],
            "mix of profiles",
        ),
    ];
    // A device is a typed flag (as in enhance): an unknown one is a usage
    // error, exit 2, in clap's format.
    let bad = pgrf(&["train", "denoiser", "--device", "tpu", "-o", s(&out)]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("unknown device"));
    let bad = pgrf(&["train", "denoiser", "--kernels", "mkl", "-o", s(&out)]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("expected pgrf or burn"));
    for (args, needle) in cases {
        let e = one_line_error(&pgrf(&args));
        assert!(e.contains(needle), "{args:?}: {e}");
    }
    if !cfg!(feature = "cuda") {
        let e = one_line_error(&pgrf(&[
            "train",
            "denoiser",
            "--device",
            "cuda",
            "-o",
            s(&out),
        ]));
        assert!(e.contains("without CUDA"), "{e}");
    }
    // The config and the two data folders stay the only entries.
    let names: Vec<_> = std::fs::read_dir(&d)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 3, "{names:?}");
}

#[test]
fn ctrl_c_checkpoints_and_exits_130_and_the_run_resumes() {
    let d = scratch("sigint");
    let out = d.join("m.safetensors");
    let log = out.with_extension("log.csv");
    let child = Command::new(env!("CARGO_BIN_EXE_pgrf"))
        .args([
            "train",
            "denoiser",
            "--steps",
            "100000",
            "--width",
            "4",
            "--log-every",
            "1",
            "--val-pairs",
            "0",
            "-o",
            s(&out),
        ])
        .args(&SMALL[..8])
        .stderr(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until a few steps are logged, then interrupt like Ctrl-C does.
    let t0 = std::time::Instant::now();
    while std::fs::read_to_string(&log)
        .map(|l| l.lines().count())
        .unwrap_or(0)
        < 4
    {
        assert!(t0.elapsed().as_secs() < 120, "training did not start");
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let pid = child.id().to_string();
    assert!(Command::new("kill")
        .args(["-INT", &pid])
        .status()
        .unwrap()
        .success());
    // A supervisor such as `timeout -s INT` delivers one request twice (to
    // the process and to its group): a second SIGINT right after the first
    // must not turn the clean stop into an exit without saving. (The run
    // may already have finished saving; then this kill finds no process.)
    std::thread::sleep(std::time::Duration::from_millis(50));
    let _ = Command::new("kill").args(["-INT", &pid]).status();
    let res = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&res.stderr);
    assert_eq!(res.status.code(), Some(130), "{err}");
    assert!(err.contains("interrupted at step"), "{err}");
    assert!(out.exists() && out.with_extension("ckpt").exists());
    let step: u64 = err
        .split("interrupted at step ")
        .nth(1)
        .and_then(|r| r.split(':').next())
        .and_then(|n| n.trim().parse().ok())
        .expect("step in message");
    let mut args = vec![
        "train",
        "denoiser",
        "--steps",
        "0",
        "--width",
        "4",
        "--val-pairs",
        "0",
        "-o",
        s(&out),
        "--resume",
    ];
    args.extend_from_slice(&SMALL[..8]);
    args.extend_from_slice(&["--quiet", "--json"]);
    let steps = (step + 2).to_string();
    args[3] = &steps;
    let j = summary(&pgrf(&args));
    assert_eq!(j["steps"].as_u64(), Some(step + 2));
    assert_eq!(j["steps_this_run"], 2);
}

/// `--print-config` writes the merged configuration as TOML, and that text
/// is itself a `--config` file giving the same configuration.
#[test]
fn print_config_round_trips_through_a_config_file() {
    let d = scratch("printcfg");
    // The noise model under its name, or under `--noise`, its old one.
    let printed = |noise_flag| {
        pgrf(&[
            "train",
            "flow",
            "--steps",
            "17",
            "--channel-mults",
            "1,2",
            noise_flag,
            "eld",
            "--print-config",
        ])
    };
    let out = printed("--noise-model");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("steps = 17"), "{text}");
    assert!(text.contains("channel_mults = [1, 2]"), "{text}");
    assert!(text.contains("noise = \"eld\""), "{text}");
    assert!(text.contains("ratio_max = 300.0"), "{text}");
    let cfg = d.join("c.toml");
    std::fs::write(&cfg, &text).unwrap();
    let again = pgrf(&["train", "flow", "--config", s(&cfg), "--print-config"]);
    assert_eq!(String::from_utf8(again.stdout).unwrap(), text);
    // --noise, the old name of --noise-model, still works with a note.
    let old = printed("--noise");
    assert_eq!(String::from_utf8(old.stdout).unwrap(), text);
    let err = String::from_utf8_lossy(&old.stderr);
    assert_eq!(
        err.lines().filter(|l| l.contains("note:")).collect::<Vec<_>>(),
        ["pgrf: note: `train --noise` is now `train --noise-model`; the old spelling goes in the next release"],
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&d);
}

/// A folder of small photos written here (PNG, distinct seeded textures),
/// plus one broken JPEG.
fn photo_folder(d: &Path) -> PathBuf {
    let dir = d.join("photos");
    std::fs::create_dir_all(&dir).unwrap();
    for k in 0..4u32 {
        let img = image::RgbImage::from_fn(96, 80, |x, y| {
            let v = |c: u32| ((x * (2 + c + k) + y * (3 + 2 * c) + 40 * k) % 256) as u8;
            image::Rgb([v(0), v(1), v(2)])
        });
        img.save(dir.join(format!("p{k}.png"))).unwrap();
    }
    std::fs::write(dir.join("broken.jpg"), b"\xff\xd8\xff\xe0 cut short").unwrap();
    dir
}

#[test]
fn photos_train_mixed_with_procedural_and_a_broken_photo_is_one_warning() {
    let d = scratch("photos");
    let photos = photo_folder(&d);
    let out = d.join("p.safetensors");
    let data = format!("{}@3,procedural@1", photos.display());
    let args = [
        "train",
        "spc",
        "--data",
        &data,
        "--patch",
        "16",
        "--batch",
        "2",
        "--steps",
        "2",
        "--width",
        "4",
        "--val-pairs",
        "2",
        "--val-every",
        "0",
        "--quiet",
        "--json",
        "-o",
        s(&out),
    ];
    let run = pgrf(&args);
    let sum = summary(&run);
    assert_eq!(sum["steps"], 2);
    assert!(sum["val_psnr"].as_f64().unwrap().is_finite());
    let err = String::from_utf8_lossy(&run.stderr);
    let warnings: Vec<&str> = err.lines().filter(|l| l.contains("warning")).collect();
    assert_eq!(warnings.len(), 1, "{err}");
    assert!(
        warnings[0].starts_with("pgrf: warning: skipped") && warnings[0].contains("broken.jpg"),
        "{err}"
    );
    // Bad photo settings: one line each, nothing written.
    let bad = d.join("bad.safetensors");
    let only_broken = d.join("broken");
    std::fs::create_dir_all(&only_broken).unwrap();
    std::fs::copy(photos.join("broken.jpg"), only_broken.join("b.jpg")).unwrap();
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["--data".into(), format!("{}@x", photos.display())],
            "weight",
        ),
        (
            vec!["--data".into(), s(&only_broken).into()],
            "no usable photo",
        ),
        (
            vec![
                "--data".into(),
                s(&photos).into(),
                "--profile".into(),
                "nikon-d850".into(),
            ],
            "--camera-like",
        ),
        (vec!["--iso-range".into(), "6400,800".into()], "iso-range"),
        (
            vec!["--iso-range".into(), "10,200".into()],
            "ISO 10 is outside",
        ),
    ];
    for (extra, needle) in cases {
        let mut a: Vec<String> = ["train", "spc", "--patch", "16", "--steps", "1", "-o"]
            .iter()
            .map(|v| v.to_string())
            .collect();
        a.push(s(&bad).into());
        a.extend(extra);
        let refs: Vec<&str> = a.iter().map(|v| v.as_str()).collect();
        let e = one_line_error(&pgrf(&refs));
        assert!(e.contains(needle), "{a:?}: {e}");
        assert!(!bad.exists());
    }
}

/// Issue 36's fine-tuning path: a blind network's weights start a
/// sigma-map run (its record names the file), the moving average is what
/// the file holds and is validated against the raw weights (log column,
/// record), and a run stopped halfway resumes to the same bytes: the
/// average is in the checkpoint. Starting from another network, and a decay
/// outside (0, 1), are one-line errors.
#[test]
fn a_noise_aware_run_starts_from_blind_weights_and_its_average_resumes() {
    let d = scratch("ema");
    let blind = d.join("blind.safetensors");
    let base = |steps: &'static str, out: &Path, extra: &[&str]| {
        let mut a = vec![
            "train",
            "denoiser",
            "--steps",
            steps,
            "--width",
            "4",
            "--residual",
            "-o",
        ];
        a.push(s(out));
        a.extend_from_slice(&["--schedule", "constant"]);
        a.extend_from_slice(SMALL);
        a.extend_from_slice(extra);
        a.iter().map(|x| x.to_string()).collect::<Vec<String>>()
    };
    let run = |args: Vec<String>| pgrf(&args.iter().map(String::as_str).collect::<Vec<_>>());
    summary(&run(base("3", &blind, &[])));
    let aware: &[&str] = &[
        "--conditioning",
        "sigma-map",
        "--init",
        s(&blind),
        "--ema",
        "0.9",
    ];
    let full = d.join("full.safetensors");
    let done = summary(&run(base("6", &full, aware)));
    assert!(done["val_psnr"].as_f64().unwrap().is_finite());
    let meta = record(&full);
    assert_eq!(meta["config"]["conditioning"], "sigma-map");
    assert_eq!(meta["config"]["in_channels"], 8);
    assert_eq!(meta["training"]["config"]["ema"].as_f64(), Some(0.9));
    assert_eq!(
        meta["training"]["started_from"]["file"],
        "blind.safetensors"
    );
    assert_eq!(meta["training"]["started_from"]["steps"], 3);
    let (stored, raw) = (
        meta["training"]["val_psnr"].as_f64().unwrap(),
        meta["training"]["val_psnr_raw"].as_f64().unwrap(),
    );
    assert!(
        stored.is_finite() && raw.is_finite() && stored != raw,
        "{stored} {raw}"
    );
    let log = std::fs::read_to_string(full.with_extension("log.csv")).unwrap();
    assert!(
        log.starts_with("step,loss,lr,images_per_s,val_psnr,seconds,val_psnr_raw\n"),
        "{log}"
    );
    let last = log.lines().last().unwrap();
    assert!(last.starts_with("6,") && !last.ends_with(','), "{log}");

    let half = d.join("half.safetensors");
    summary(&run(base("3", &half, aware)));
    let mut more = base("6", &half, aware);
    more.push("--resume".into());
    let resumed = summary(&run(more));
    assert_eq!(resumed["steps_this_run"], 3);
    let tensors = |p: &Path| {
        let b = std::fs::read(p).unwrap();
        let n = u64::from_le_bytes(b[..8].try_into().unwrap()) as usize;
        b[8 + n..].to_vec()
    };
    assert!(tensors(&half) == tensors(&full), "resumed average differs");

    let wide = d.join("wide.safetensors");
    let mut other = base("6", &wide, aware);
    other[5] = "8".into();
    let err = one_line_error(&run(other));
    assert!(
        err.contains("without its noise conditioning") && err.contains("width 4"),
        "{err}"
    );
    assert!(!wide.exists());
    let bad = base("6", &wide, &["--ema", "1.5"]);
    let err = one_line_error(&run(bad));
    assert!(err.contains("--ema") && err.contains("(0, 1)"), "{err}");
}

/// `--window` (issue 36, item 6): a flow model trained within windows of
/// its crops records the window, and restores with it; one trained without
/// restores within windows of its crop; windows that do not divide the
/// crops, and windows for the SPC, are one-line errors before any work.
#[test]
fn a_flow_model_trained_within_windows_restores_with_them() {
    let d = scratch("window");
    let train = |out: &Path, extra: &[&str]| {
        let mut args = vec![
            "train",
            "flow",
            "--steps",
            "2",
            "--patch",
            "32",
            "--inner-channels",
            "8",
            "--channel-mults",
            "1,2",
            "--attn-levels",
            "1",
            "--val-pairs",
            "1",
            "-o",
            s(out),
        ];
        args.extend_from_slice(extra);
        pgrf(&args)
    };
    let windowed = d.join("w.safetensors");
    let r = train(&windowed, &["--window", "16", "--calibrated-share", "0.25"]);
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{err}");
    assert!(
        err.contains("(32x32 crops within windows of 16, batch 1)"),
        "{err}"
    );
    assert!(
        err.contains("(25% drawn with the dark level calibrated)"),
        "{err}"
    );
    let meta = pgrf_nn::weights::read_meta(&windowed).unwrap();
    assert!(!meta.noise.calibrated_dark_level, "a share is not all");
    let config = meta.training.unwrap().config.unwrap();
    assert_eq!(config.window, Some(16));
    assert_eq!(config.calibrated_share, 0.25);
    let load = |p: &Path| {
        pgrf_nn::infer::load(
            p,
            pgrf_nn::SamplerChoice::default(),
            pgrf_nn::DeviceKind::Cpu,
        )
        .unwrap()
    };
    assert_eq!(load(&windowed).window(), 16);
    let whole = d.join("c.safetensors");
    let r = train(&whole, &[]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert_eq!(load(&whole).window(), 32, "the crop side");
    for (method, extra, says) in [
        ("flow", vec!["--window", "12"], "must divide --patch 32"),
        (
            "flow",
            vec!["--window", "16", "--val-patch", "40"],
            "must divide --val-patch 40",
        ),
        (
            "spc",
            vec!["--window", "16"],
            "the SPC denoiser takes no statistics",
        ),
        (
            "spc",
            vec!["--calibrated-share", "1.5"],
            "in [0, 1], got 1.5",
        ),
        (
            "spc",
            vec!["--calibrated-share", "0.5", "--calibrated-dark-level"],
            "goes without --calibrated-dark-level",
        ),
    ] {
        let bad = d.join("bad.safetensors");
        let mut args = vec!["train", method, "--patch", "32", "-o", s(&bad)];
        args.extend_from_slice(&extra);
        let e = one_line_error(&pgrf(&args));
        assert!(e.contains(says), "{e}");
        assert!(!bad.exists());
    }
}

/// Issue 51's training settings reach the files that record them: a run
/// with values below black kept and crops weighted by their own MSE says so
/// in its header, its network's configuration keeps the input convention
/// (so every command feeds it unclamped), its training record the loss, and
/// it starts from weights trained on clamped input.
#[test]
fn values_below_black_and_the_loss_are_recorded() {
    let d = scratch("below-black");
    let train = |out: &Path, extra: &[&str]| {
        let mut args = vec![
            "train",
            "spc",
            "--steps",
            "2",
            "--patch",
            "32",
            "--batch",
            "2",
            "--width",
            "4",
            "--val-pairs",
            "1",
            "--workers",
            "1",
            "-o",
            s(out),
        ];
        args.extend_from_slice(extra);
        pgrf(&args)
    };
    let clamped = d.join("clamped.safetensors");
    let r = train(&clamped, &[]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let kept = d.join("kept.safetensors");
    let r = train(
        &kept,
        &[
            "--keep-below-black",
            "--item-weight",
            "log",
            "--loss",
            "mse",
            "--init",
            s(&clamped),
        ],
    );
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{err}");
    assert!(err.contains("values below black kept"), "{err}");
    assert!(
        err.contains("loss the mean of ln MSE over the crops"),
        "{err}"
    );
    let meta = pgrf_nn::weights::read_meta(&kept).unwrap();
    assert!(meta.arch.keeps_below_black());
    let config = meta.training.unwrap().config.unwrap();
    assert!(config.keep_below_black);
    assert_eq!(config.item_weight, pgrf_nn::ItemWeight::Log);
    assert_eq!(config.loss, pgrf_nn::Distance::Mse);
    // The clamped run's record has neither key (older readers see nothing new).
    let clamped_record = record(&clamped);
    assert_eq!(clamped_record["config"]["keep_below_black"], false);
    let training = &clamped_record["training"]["config"];
    assert!(training.get("item_weight").is_none() && training.get("loss").is_none());
}

/// Issue 51, lever 5: a flow trained with `--prior` carries the denoiser
/// in its own file, bit for bit, and (its last layer starting at zero)
/// restores what the denoiser does, however different that is from the
/// noisy input; a prior that is not a denoiser, or one for the denoiser, is
/// refused in one line.
#[test]
fn a_flow_with_a_prior_restores_what_its_denoiser_does() {
    let d = scratch("prior");
    let spc = d.join("spc.safetensors");
    let mut a = vec!["train", "spc", "--steps", "2", "--width", "4"];
    // Not residual: its restoration is far from the input it is given.
    a.extend_from_slice(&["-o", s(&spc)]);
    a.extend_from_slice(SMALL);
    summary(&pgrf(&a));
    let flow = d.join("flow.safetensors");
    let mut f = vec!["train", "flow", "--steps", "1", "--lr", "1e-30"];
    f.extend_from_slice(&["--inner-channels", "8", "--channel-mults", "1,2"]);
    f.extend_from_slice(&["--attn-levels", "1", "--residual"]);
    f.extend_from_slice(&["--prior", s(&spc), "-o", s(&flow)]);
    f.extend_from_slice(SMALL);
    summary(&pgrf(&f));
    let rec = record(&flow);
    assert_eq!(rec["arch"], "sr3-prior");
    assert_eq!(rec["config"]["prior"]["width"], 4);
    assert_eq!(rec["config"]["flow"]["in_channels"], 12);
    let (_, denoiser) = pgrf_nn::weights::read(&spc).unwrap();
    let (_, field) = pgrf_nn::weights::read(&flow).unwrap();
    for (name, t) in &denoiser {
        assert_eq!(&field[&format!("prior.{name}")], t, "{name}");
    }

    let load = |p: &Path| {
        pgrf_nn::infer::load(
            p,
            pgrf_nn::SamplerChoice::default(),
            pgrf_nn::DeviceKind::Cpu,
        )
        .unwrap()
    };
    let wave = |k: f32| {
        pgrf_raw::ndarray::Array3::from_shape_fn((4, 32, 32), |(c, y, x)| {
            0.3 + 0.25 * ((c * 1024 + y * 32 + x) as f32 * k).sin()
        })
    };
    let (noisy, x0) = (wave(0.37), wave(1.91));
    let by_spc = load(&spc)
        .restore(noisy.view(), &[x0.view()], None)
        .unwrap();
    let by_flow = load(&flow)
        .restore(noisy.view(), &[x0.view()], None)
        .unwrap();
    let most = |a: &pgrf_raw::ndarray::Array3<f32>, b: &pgrf_raw::ndarray::Array3<f32>| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max)
    };
    assert!(
        most(&by_spc, &by_flow) < 1e-5,
        "{}",
        most(&by_spc, &by_flow)
    );
    assert!(most(&by_spc, &noisy) > 0.01, "{}", most(&by_spc, &noisy));

    for (method, prior, says) in [
        ("flow", &flow, "not an SPC denoiser"),
        ("spc", &spc, "--prior starts a flow model"),
    ] {
        let bad = d.join("bad.safetensors");
        let mut args = vec!["train", method, "--patch", "32", "--prior", s(prior)];
        args.extend_from_slice(&["-o", s(&bad)]);
        let e = one_line_error(&pgrf(&args));
        assert!(e.contains(says), "{e}");
        assert!(!bad.exists());
    }
}
