//! Every weight file pgrf writes loads back (issue 37, finding 3): a resume
//! of a finished run leaves its file as it was, a lost file is written again
//! from the checkpoint with the checkpoint's loss, `--steps 0` and a
//! checkpoint past `--steps` are refused, files an older pgrf wrote with a
//! null loss load, and `export-weights` refuses a record its tensors do not
//! fit instead of exporting them.

mod common;
use common::{one_line_error, pgrf, s, scratch};

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Output;

fn summary(out: &Output) -> Value {
    assert!(
        out.status.success(),
        "pgrf failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(text.lines().last().expect("a JSON line")).expect("JSON summary")
}

/// The arguments of a denoiser run of width 4 for `steps` steps writing
/// `out` (and its checkpoint).
fn train_args<'a>(out: &'a Path, steps: &'a str) -> Vec<&'a str> {
    vec![
        "train",
        "denoiser",
        "--steps",
        steps,
        "--width",
        "4",
        "--patch",
        "32",
        "--batch",
        "2",
        "--seed",
        "3",
        "--val-pairs",
        "2",
        "--iso",
        "1600",
        "--data",
        "procedural",
        "-o",
        s(out),
    ]
}

/// That run, quiet with its JSON summary, with `extra` flags.
fn train(out: &Path, steps: &str, extra: &[&str]) -> Output {
    let mut args = train_args(out, steps);
    args.extend_from_slice(&["--quiet", "--json"]);
    args.extend_from_slice(extra);
    pgrf(&args)
}

/// The safetensors header and the rest of a weight file.
fn split(p: &Path) -> (Value, Vec<u8>) {
    let b = std::fs::read(p).unwrap();
    let n = u64::from_le_bytes(b[..8].try_into().unwrap()) as usize;
    (
        serde_json::from_slice(&b[8..8 + n]).unwrap(),
        b[8 + n..].to_vec(),
    )
}

/// The pgrf record of a weight file.
fn record(p: &Path) -> Value {
    let (h, _) = split(p);
    serde_json::from_str(h["__metadata__"]["pgrf"].as_str().unwrap()).unwrap()
}

/// `p` again at `to`, its record changed by `f` (tensors untouched).
fn edit_record(p: &Path, to: &Path, f: impl FnOnce(&mut Value)) {
    let (mut h, tensors) = split(p);
    let mut rec = record(p);
    f(&mut rec);
    h["__metadata__"]["pgrf"] = Value::String(rec.to_string());
    let mut head = serde_json::to_vec(&h).unwrap();
    while head.len() % 8 != 0 {
        head.push(b' ');
    }
    let mut b = (head.len() as u64).to_le_bytes().to_vec();
    b.extend_from_slice(&head);
    b.extend_from_slice(&tensors);
    std::fs::write(to, b).unwrap();
}

/// `enhance` runs `model` on a small chart: the file loads.
fn enhances(dir: &Path, model: &Path) -> Output {
    let chart = dir.join("c.dng");
    if !chart.exists() {
        let r = pgrf(&["chart", "-o", s(&chart), "--width", "128", "--height", "96"]);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    }
    pgrf(&[
        "enhance",
        s(&chart),
        "--model",
        s(model),
        "--ratio",
        "20",
        "-o",
        s(&dir.join("e.dng")),
    ])
}

#[test]
fn resuming_a_finished_run_leaves_its_file_and_every_file_written_loads() {
    let d = scratch("loadable", "resume");
    let out = d.join("m.safetensors");
    let first = summary(&train(&out, "2", &[]));
    let loss = first["final_loss"].as_f64().unwrap();
    assert!(loss > 0.0 && loss.is_finite(), "{first}");
    let bytes = std::fs::read(&out).unwrap();

    // Resumed again, finished: said so, nothing trained, the file as it was.
    let again = summary(&train(&out, "2", &["--resume"]));
    assert_eq!(again["already_finished"], true, "{again}");
    assert_eq!(again["steps"], 2);
    assert_eq!(again["steps_this_run"], 0);
    assert_eq!(again["final_loss"].as_f64(), Some(loss));
    assert!(
        std::fs::read(&out).unwrap() == bytes,
        "the weight file changed"
    );
    let r = enhances(&d, &out);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    // Without --json the line says so.
    let mut args = train_args(&out, "2");
    args.push("--resume");
    let r = pgrf(&args);
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(
        r.status.success() && err.contains("already finished"),
        "{err}"
    );

    // The weight file lost after the last checkpoint: written again from the
    // checkpoint, with the loss of the checkpoint's last step (never null).
    let tensors = split(&out).1;
    std::fs::remove_file(&out).unwrap();
    let rewritten = summary(&train(&out, "2", &["--resume"]));
    assert_eq!(rewritten["already_finished"], false);
    assert_eq!(rewritten["final_loss"].as_f64(), Some(loss));
    let rec = record(&out);
    assert_eq!(
        rec["training"]["final_loss"].as_f64().map(|l| l as f32),
        Some(loss as f32)
    );
    assert!(split(&out).1 == tensors, "the checkpoint's weights differ");
    let r = enhances(&d, &out);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    // ...and a resume after that is finished again.
    assert_eq!(
        summary(&train(&out, "2", &["--resume"]))["already_finished"],
        true
    );

    // A checkpoint past --steps: refused, the file untouched.
    let kept = std::fs::read(&out).unwrap();
    let e = one_line_error(&train(&out, "1", &["--resume"]));
    assert!(
        e.contains("at step 2, past --steps 1") && e.contains("--steps 2 or more"),
        "{e}"
    );
    assert!(std::fs::read(&out).unwrap() == kept);

    // A file an older pgrf wrote after resuming a finished run (loss null)
    // loads.
    let null = d.join("null.safetensors");
    edit_record(&out, &null, |r| r["training"]["final_loss"] = Value::Null);
    assert!(record(&null)["training"]["final_loss"].is_null());
    let r = enhances(&d, &null);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
}

/// `--steps 0` alone would record random weights as a trained model: refused,
/// nothing written. With `--init` it copies that file's weights (a
/// fine-tuning of no step, which has no loss): the file loads.
#[test]
fn steps_zero_is_refused_alone_and_loads_with_init() {
    let d = scratch("loadable", "zero");
    let out = d.join("z.safetensors");
    let e = one_line_error(&train(&out, "0", &[]));
    assert!(e.contains("--steps 0 trains nothing"), "{e}");
    let left: Vec<PathBuf> = std::fs::read_dir(&d)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert!(left.is_empty(), "{left:?}");

    let init = d.join("i.safetensors");
    summary(&train(&init, "2", &[]));
    let copy = summary(&train(&out, "0", &["--init", s(&init)]));
    assert_eq!(
        (copy["steps"].as_u64(), copy["final_loss"].as_f64()),
        (Some(0), None)
    );
    assert!(record(&out)["training"]["final_loss"].is_null());
    assert!(split(&out).1 == split(&init).1);
    let r = enhances(&d, &out);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
}

#[test]
fn export_refuses_a_record_its_tensors_do_not_fit() {
    let d = scratch("loadable", "export");
    let good = common::tiny_model(&d, false, None, 5);
    // The genuine file exports.
    let r = pgrf(&["export-weights", s(&good), "-o", s(&d.join("ok.pth"))]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    for (name, width) in [("huge", 100_000_000u64), ("wider", 8)] {
        let bad = d.join(format!("{name}.safetensors"));
        edit_record(&good, &bad, |r| r["config"]["width"] = width.into());
        for to in ["x.pth", "x.safetensors"] {
            let to = d.join(format!("{name}_{to}"));
            let e = one_line_error(&pgrf(&["export-weights", s(&bad), "-o", s(&to)]));
            assert!(
                e.contains("weights do not fit")
                    && e.contains("the file holds")
                    && e.contains(&format!("width {width}")),
                "{e}"
            );
            assert!(!to.exists());
        }
    }
    // A tensor of the wrong shape under the right record: the same values
    // as one flat row.
    let (mut h, tensors) = split(&good);
    let entry = h
        .as_object()
        .unwrap()
        .iter()
        .find(|(_, v)| v["shape"].as_array().is_some_and(|a| a.len() == 4))
        .map(|(k, _)| k.clone())
        .expect("a convolution");
    let n: u64 = h[&entry]["shape"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .product();
    h[&entry]["shape"] = serde_json::json!([n]);
    let mut head = serde_json::to_vec(&h).unwrap();
    while head.len() % 8 != 0 {
        head.push(b' ');
    }
    let mut b = (head.len() as u64).to_le_bytes().to_vec();
    b.extend_from_slice(&head);
    b.extend_from_slice(&tensors);
    let bad = d.join("shape.safetensors");
    std::fs::write(&bad, b).unwrap();
    let to = d.join("shape.pth");
    let e = one_line_error(&pgrf(&["export-weights", s(&bad), "-o", s(&to)]));
    assert!(
        e.contains("weights do not fit") && e.contains(&format!("{entry} has shape [{n}]")),
        "{e}"
    );
    assert!(!to.exists());
}
