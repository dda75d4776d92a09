//! `pgrf profiles` and `--profile darktable:"MAKER MODEL"` end to end, on a
//! noiseprofiles.json in darktable's exact format given with the global
//! `--darktable-profiles PATH`: listing, showing, synthesising, refusing.

mod common;

use common::{one_line_error, pgrf, s, scratch};
use std::path::{Path, PathBuf};

const FIXTURE: &str = r#"{
  "version": 0,
  "noiseprofiles": [
    {
      "maker": "Testmaker",
      "models": [
        {
          "comment": "three ISOs and a skipped entry",
          "model": "TM-1",
          "profiles": [
            {"name": "TM-1 iso 100", "iso": 100, "a": [8.0e-06, 5.0e-06, 6.0e-06], "b": [4.0e-08, 5.0e-08, 6.0e-08]},
            {"name": "TM-1 iso 400", "iso": 400, "a": [3.0e-05, 2.0e-05, 2.5e-05], "b": [1.0e-07, 2.0e-07, 1.5e-07]},
            {"name": "TM-1 iso 1600", "iso": 1600, "a": [1.2e-04, 8.0e-05, 1.0e-04], "b": [5.0e-07, 6.0e-07, 7.0e-07]},
            {"skip": true, "name": "TM-1 iso 6400", "iso": 6400, "a": [4.0e-04, 3.0e-04, 3.5e-04], "b": [2.0e-06, 2.0e-06, 2.0e-06]}
          ]
        }
      ]
    },
    {
      "maker": "Othermaker",
      "models": [
        {
          "comment": "a green b below zero",
          "model": "OM 5",
          "profiles": [
            {"name": "OM 5 iso 200", "iso": 200, "a": [2.0e-05, 2.0e-05, 2.0e-05], "b": [1.0e-07, -3.0e-07, 1.0e-07]},
            {"name": "OM 5 iso 400", "iso": 400, "a": [4.0e-05, 4.0e-05, 4.0e-05], "b": [1.0e-07, 1.0e-07, 1.0e-07]}
          ]
        }
      ]
    }
  ]
}
"#;

fn fixture(dir: &Path, text: &str) -> PathBuf {
    let p = dir.join("noiseprofiles.json");
    std::fs::write(&p, text).unwrap();
    p
}

fn stdout(out: &std::process::Output) -> String {
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "failed: {err}");
    String::from_utf8_lossy(&out.stdout).to_string()
}

/// `profiles list --darktable` lists the built-ins and every camera with
/// its measured ISOs (the skipped ISO 6400 left out); `profiles show`
/// prints darktable's green numbers, pgrf's K and read sigma per ISO
/// (12.9 a x 16383, sqrt(12.9 b) x 16383), the source and the limits.
#[test]
fn list_and_show_print_darktables_cameras() {
    let dir = scratch("profiles", "list");
    let f = fixture(&dir, FIXTURE);
    let list = stdout(&pgrf(&[
        "--darktable-profiles",
        s(&f),
        "profiles",
        "list",
        "--darktable",
    ]));
    // Each line with its runs of spaces (column padding) collapsed.
    let lines: Vec<String> = list
        .lines()
        .map(|l| l.split_whitespace().collect::<Vec<_>>().join(" "))
        .collect();
    for says in [
        "sony-a7s2 Sony ILCE-7SM2 ISO 50..25600 (28 ISOs)",
        "Testmaker TM-1 ISO 100 400 1600",
        "Othermaker OM 5 ISO 200 400",
    ] {
        assert!(lines.iter().any(|l| l == says), "{says}: {list}");
    }
    assert!(
        list.contains("canon-eos700d") && list.contains("2 cameras"),
        "{list}"
    );
    // The option is global: after the subcommand too.
    let again = stdout(&pgrf(&[
        "profiles",
        "list",
        "--darktable",
        "--darktable-profiles",
        s(&f),
    ]));
    assert_eq!(again, list);
    let show = stdout(&pgrf(&[
        "--darktable-profiles",
        s(&f),
        "profiles",
        "show",
        "darktable:Testmaker TM-1",
        "--iso",
        "1000",
    ]));
    for says in [
        "profile   darktable:Testmaker TM-1",
        "format version 0",
        "measured at ISO 100, 400, 1600",
        "no row noise, no fixed pattern, no heavy-tailed (Tukey) read noise, no dark current",
        "white - black = 16383 DN",
        // ISO 400: K = 12.9 x 2e-5 x 16383, sigma = sqrt(12.9 x 2e-7) x 16383.
        "4.22681",
        "26.3150",
    ] {
        assert!(show.contains(says), "{says}: {show}");
    }
    // ISO 1000, linear in ISO between 400 and 1600: a 5e-5, b 4e-7, so
    // K = 10.56704 and sigma = 37.21502 (to the table's 3e-6).
    let at = show
        .lines()
        .find_map(|l| l.strip_prefix("at ISO 1000: K "))
        .expect("an --iso line");
    let num = |t: &str| t.split_whitespace().next().unwrap().parse::<f64>().unwrap();
    let k = num(at);
    let sigma = num(at.split("read sigma ").nth(1).unwrap());
    assert!((k / 10.56704 - 1.0).abs() < 1e-5, "{at}");
    assert!((sigma / 37.21502 - 1.0).abs() < 1e-5, "{at}");
    assert!(!show.contains("6400"), "{show}");
    let neg = stdout(&pgrf(&[
        "--darktable-profiles",
        s(&f),
        "profiles",
        "show",
        "darktable:othermaker om 5",
    ]));
    assert!(neg.contains("b < 0: no read noise resolved"), "{neg}");
    // Built-ins need no darktable file.
    let a7 = stdout(&pgrf(&["profiles", "show", "sony-a7s2", "--iso", "1600"]));
    assert!(
        a7.contains("28 ISOs") && a7.contains("at ISO 1600: K 1.53008"),
        "{a7}"
    );
}

/// `synth --profile darktable:"MAKER MODEL"` writes the dark capture at the
/// camera's interpolated parameters, for every noise model.
#[test]
fn synth_takes_a_darktable_camera() {
    let dir = scratch("profiles", "synth");
    let f = fixture(&dir, FIXTURE);
    let demo = pgrf(&["demo", "-o", s(&dir), "--size", "128x96", "--quiet"]);
    assert!(
        demo.status.success(),
        "{}",
        String::from_utf8_lossy(&demo.stderr)
    );
    let clean = dir.join("clean.dng");
    for model in ["pg", "eld", "pgrf"] {
        let out_path = dir.join(format!("dark_{model}.dng"));
        let out = pgrf(&[
            "--darktable-profiles",
            s(&f),
            "synth",
            s(&clean),
            "--profile",
            "darktable:Testmaker TM-1",
            "--iso",
            "1000",
            "--ratio",
            "100",
            "--model",
            model,
            "-o",
            s(&out_path),
        ]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{model}: {err}");
        // K = 12.9 x 5e-5 x 16383 = 10.567035 (to the table's 3e-6).
        let k: f64 = err
            .split("ISO 1000, K ")
            .nth(1)
            .and_then(|t| t.split_whitespace().next())
            .and_then(|t| t.parse().ok())
            .unwrap_or_else(|| panic!("{model}: {err}"));
        assert!(
            (k / 10.567035 - 1.0).abs() < 2e-5 && err.contains("ratio 100.0"),
            "{model}: {err}"
        );
        let info = stdout(&pgrf(&["info", s(&out_path)]));
        assert!(info.contains("1000"), "{info}");
    }
}

/// A missing file, an unknown camera, a malformed entry, a negative green
/// slope, an ISO outside the measured ones: one line each, exit 1.
#[test]
fn bad_darktable_inputs_are_one_line_errors() {
    let dir = scratch("profiles", "bad");
    let good = fixture(&dir, FIXTURE);
    let demo = pgrf(&["demo", "-o", s(&dir), "--size", "128x96", "--quiet"]);
    assert!(demo.status.success());
    let clean = dir.join("clean.dng");
    let out_path = dir.join("dark.dng");
    let synth = |file: &Path, camera: &str, iso: &str| {
        pgrf(&[
            "--darktable-profiles",
            s(file),
            "synth",
            s(&clean),
            "--profile",
            &format!("darktable:{camera}"),
            "--iso",
            iso,
            "--ratio",
            "100",
            "-o",
            s(&out_path),
        ])
    };
    let missing = dir.join("nowhere.json");
    for (out, says) in [
        (
            synth(&missing, "Testmaker TM-1", "400"),
            vec!["cannot read", "nowhere.json"],
        ),
        (
            pgrf(&[
                "--darktable-profiles",
                s(&missing),
                "profiles",
                "list",
                "--darktable",
            ]),
            vec!["nowhere.json"],
        ),
        (
            synth(&good, "Testmaker TM-2", "400"),
            vec![
                "no such camera",
                "closest: \"Testmaker TM-1\", \"Othermaker OM 5\"",
            ],
        ),
        (
            synth(&good, "Testmaker TM-1", "3200"),
            vec!["ISO 3200", "100..=1600"],
        ),
    ] {
        let e = one_line_error(&out);
        for s in says {
            assert!(e.contains(s), "{s}: {e}");
        }
    }
    let bad = |name: &str, text: String| {
        let d = dir.join(name);
        std::fs::create_dir_all(&d).unwrap();
        fixture(&d, &text)
    };
    let short = bad(
        "short",
        FIXTURE.replacen(
            "\"b\": [1.0e-07, 2.0e-07, 1.5e-07]",
            "\"b\": [1.0e-07, 2.0e-07]",
            1,
        ),
    );
    let e = one_line_error(&synth(&short, "Testmaker TM-1", "400"));
    assert!(
        e.contains("Testmaker TM-1, entry 2 of 4 (\"TM-1 iso 400\")")
            && e.contains("`b` has 2 values"),
        "{e}"
    );
    let e = one_line_error(&pgrf(&[
        "--darktable-profiles",
        s(&short),
        "profiles",
        "show",
        "darktable:Othermaker OM 5",
    ]));
    assert!(e.contains("TM-1 iso 400"), "{e}");
    let negative = bad(
        "negative",
        FIXTURE.replacen("1.2e-04, 8.0e-05", "1.2e-04, -8.0e-05", 1),
    );
    let e = one_line_error(&synth(&negative, "Testmaker TM-1", "400"));
    assert!(e.contains("green a = -0.00008 at ISO 1600"), "{e}");
    assert!(!out_path.exists());
}

/// `--darktable-profiles` is handed to every command that loads a profile
/// (configuration, not process state): `train` and `eval --protocol
/// synthetic` take the fixture's camera with it, and without it (darktable's
/// install has no "Testmaker", or there is none) they are refused in one
/// line.
#[test]
fn train_and_eval_take_the_darktable_file_given() {
    let dir = scratch("profiles", "train");
    let f = fixture(&dir, FIXTURE);
    let demo = pgrf(&["demo", "-o", s(&dir), "--size", "128x96", "--quiet"]);
    assert!(demo.status.success());
    let out = dir.join("t.safetensors");
    let train = |with: bool| {
        let mut a = vec![];
        if with {
            a.extend(["--darktable-profiles", s(&f)]);
        }
        a.extend([
            "train",
            "denoiser",
            "--profile",
            "darktable:Testmaker TM-1",
            "--iso",
            "1000",
            "--steps",
            "1",
            "--width",
            "4",
            "--patch",
            "32",
            "--batch",
            "1",
            "--val-pairs",
            "0",
            "--data",
            "procedural",
            "--quiet",
            "-o",
            s(&out),
        ]);
        pgrf(&a)
    };
    let eval = |with: bool| {
        let mut a = vec![];
        if with {
            a.extend(["--darktable-profiles", s(&f)]);
        }
        let clean = dir.join("clean.dng");
        a.extend([
            "eval",
            "--protocol",
            "synthetic",
            "--root",
            s(&clean),
            "--profile",
            "darktable:Testmaker TM-1",
            "--iso",
            "1000",
            "--ratio",
            "100",
            "--crop",
            "32",
            "--quiet",
        ]);
        pgrf(&a)
    };
    for (name, run) in [("train", &train as &dyn Fn(bool) -> _), ("eval", &eval)] {
        let r = run(true);
        assert!(
            r.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&r.stderr)
        );
        // Without it: darktable's install has no such camera, or there is
        // no install (CI).
        let e = one_line_error(&run(false));
        assert!(
            e.contains("Testmaker TM-1") || e.contains("noiseprofiles.json was not found"),
            "{name}: {e}"
        );
    }
}
