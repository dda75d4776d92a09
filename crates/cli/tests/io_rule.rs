//! The one rule on what commands write (issue 37, finding 1): no output may
//! be an input, sit inside an input folder or, as a folder, hold an input,
//! and two outputs may not share a path. Each case below once destroyed or
//! polluted an input with exit 0; now each is refused in one line before
//! any work, and leaves every file as it was.

mod common;
use common::{one_line_error, pgrf, s, scratch};
use std::collections::BTreeMap;
use std::path::Path;

/// Every file under `dir` with its bytes.
fn snapshot(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut files = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let key = p.strip_prefix(dir).unwrap().display().to_string();
                files.insert(key, std::fs::read(&p).unwrap());
            }
        }
    }
    files
}

/// The arguments `parts` joined, then `tail`.
fn argv(parts: &[&[&str]], tail: Vec<String>) -> Vec<String> {
    let mut v: Vec<String> = parts.concat().iter().map(|x| x.to_string()).collect();
    v.extend(tail);
    v
}

#[test]
fn outputs_may_not_be_inside_or_around_inputs_nor_share_a_path() {
    let d = scratch("io_rule", "cases");
    let c = d.join("c.dng");
    common::chart(&c, 64, 48);
    let w = d.join("w.safetensors");
    std::fs::write(&w, b"weights stand-in: the check runs before loading").unwrap();
    let t = d.join("t.toml");
    std::fs::write(&t, "steps = 1\n").unwrap();
    let p = d.join("p.json");
    std::fs::write(&p, "{}").unwrap();
    for stack in ["bias", "flat", "raws"] {
        std::fs::create_dir(d.join(stack)).unwrap();
        common::chart(&d.join(stack).join("f1.dng"), 64, 48);
    }
    let (bias, flat, raws) = (d.join("bias"), d.join("flat"), d.join("raws"));
    let r = d.join("r.csv");
    let inside = |dir: &Path, name: &str| dir.join(name).display().to_string();
    let (model, cal) = (inside(&d, "m.safetensors"), inside(&d, "cal.safetensors"));
    // `-o OUT` unless the case names its own `-o`.
    let default_o = |extra: &[&str], out: &str| -> Vec<String> {
        if extra.contains(&"-o") {
            Vec::new()
        } else {
            vec!["-o".into(), out.into()]
        }
    };
    let eval = |extra: &[&str]| {
        let base = ["eval", "--protocol", "synthetic", "--root", s(&c)];
        let rest = ["--model", "builtin:spc", "--ratio", "100", "--iso", "1600"];
        argv(&[&base, &rest, extra], Vec::new())
    };
    let train = |extra: &[&str]| {
        let base = ["train", "spc", "--config", s(&t)];
        argv(&[&base, extra], default_o(extra, &model))
    };
    let calibrate = |extra: &[&str]| {
        let base = ["calibrate", "--bias", s(&bias), "--flat", s(&flat)];
        argv(&[&base, extra], default_o(extra, &cal))
    };
    let enhance =
        |extra: &[&str]| argv(&[&["enhance", "--model", "builtin:spc"], extra], Vec::new());
    let cases: Vec<(Vec<String>, String)> = vec![
        // eval: the RAW, the model, the dataset folder, and itself.
        (
            eval(&["--csv", s(&c)]),
            format!("--csv {} is the input", s(&c)),
        ),
        (eval(&["--markdown", s(&c)]), "--markdown".into()),
        (eval(&["--worst", s(&c)]), "--worst".into()),
        (
            eval(&["--model", s(&w), "--csv", s(&w)]),
            "is the input".into(),
        ),
        (
            [
                "eval",
                "--protocol",
                "synthetic",
                "--root",
                s(&raws),
                "--dump",
                s(&raws),
            ]
            .iter()
            .map(|x| x.to_string())
            .collect(),
            "--dump".into(),
        ),
        (
            eval(&["--csv", s(&r), "--markdown", s(&r)]),
            "--markdown and --csv both name".into(),
        ),
        (
            eval(&[
                "--csv",
                &inside(&d, "r.csv"),
                "--worst",
                &inside(&d, "r_worst.png"),
                "--markdown",
                &inside(&d, "r_worst.png"),
            ]),
            "both name".into(),
        ),
        // train: the config, the profile, the starting weights.
        (train(&["-o", s(&t)]), "-o".into()),
        (train(&["--log", s(&t)]), "--log".into()),
        (train(&["--checkpoint", s(&t)]), "--checkpoint".into()),
        (train(&["--profile", s(&p), "--log", s(&p)]), "--log".into()),
        (
            train(&["--data", s(&raws), "--checkpoint", &inside(&raws, "m.ckpt")]),
            "(--data); write the result outside it".into(),
        ),
        // calibrate: nothing into the stacks.
        (
            calibrate(&["--masters", &inside(&bias, "masters")]),
            "--masters".into(),
        ),
        (
            calibrate(&["--report", &inside(&flat, "report")]),
            "(--flat); write".into(),
        ),
        (
            calibrate(&["-o", &inside(&bias, "cal.safetensors")]),
            "(--bias); write".into(),
        ),
        (
            calibrate(&["--report", s(&d)]),
            "(--bias); write the result into a folder".into(),
        ),
        // reduce: not into the masters folder it reads.
        (
            argv(
                &[&["reduce", s(&c), "--masters", s(&bias)]],
                vec![
                    "--calib".into(),
                    s(&p).into(),
                    "-o".into(),
                    inside(&bias, "reduced"),
                ],
            ),
            "--masters".into(),
        ),
        // enhance: not into the folder it reads, nor around it.
        (
            enhance(&[s(&raws), "-o", &inside(&raws, "clean")]),
            "inside the input folder".into(),
        ),
        (enhance(&[s(&raws), "-o", s(&d)]), "holds the input".into()),
        (
            enhance(&[s(&c), "-o", &inside(&d, "e.dng"), "--png", s(&c)]),
            "--png".into(),
        ),
    ];
    let before = snapshot(&d);
    for (args, needle) in &cases {
        let args: Vec<&str> = args.iter().map(|a| a.as_str()).collect();
        let e = one_line_error(&pgrf(&args));
        assert!(e.contains(needle.as_str()), "{args:?}: {e}");
        assert_eq!(snapshot(&d), before, "{args:?} changed the files");
    }
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn outputs_beside_the_inputs_are_written() {
    // The rule is no stricter than it says: the same commands with their
    // outputs next to (not in) the input folders run.
    let d = scratch("io_rule", "beside");
    let raws = d.join("raws");
    std::fs::create_dir(&raws).unwrap();
    common::chart(&raws.join("a.dng"), 64, 48);
    let out = d.join("clean");
    let o = pgrf(&[
        "enhance",
        s(&raws),
        "--model",
        "builtin:spc",
        "--noise",
        "K=1,read=4",
        "--ratio",
        "10",
        "-o",
        s(&out),
        "-q",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join("a.dng").is_file());
    std::fs::remove_dir_all(&d).unwrap();
}
