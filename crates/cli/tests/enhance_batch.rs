//! `pgrf enhance` batches as a cluster runs them (issue 37): shards that
//! split the work without overlap and agree with one whole run byte for
//! byte, `--skip-existing` that keeps whole outputs and redoes cut ones,
//! `--from-list`, a manifest that stays readable line by line, one bad file
//! that fails alone (exit 3), and the load-and-fault tool at CI scale.

mod common;
use common::{one_line_error, pgrf, s};

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::{Duration, SystemTime};

fn scratch(name: &str) -> PathBuf {
    common::scratch("enhance-batch", name)
}

/// `n` tiny charts `c0.dng`, `c1.dng`, ... in `dir`, each of another
/// exposure and CFA phase, so that no two outputs are alike.
fn charts(dir: &Path, n: usize) -> Vec<PathBuf> {
    std::fs::create_dir_all(dir).unwrap();
    let cfas = ["RGGB", "BGGR", "GRBG", "GBRG"];
    (0..n)
        .map(|i| {
            let path = dir.join(format!("c{i}.dng"));
            let exposure = format!("{:.2}", 0.2 + 0.07 * i as f64);
            let r = pgrf(&[
                "chart",
                "-o",
                s(&path),
                "--width",
                "64",
                "--height",
                "48",
                "--exposure",
                &exposure,
                "--cfa",
                cfas[i % 4],
            ]);
            assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
            path
        })
        .collect()
}

/// `pgrf enhance` with the built-in SPC on tiny files (noise and ratio
/// given: nothing is estimated), quiet, then `extra`.
fn enhance(extra: &[&str]) -> Output {
    enhance_in(None, extra)
}

fn enhance_in(dir: Option<&Path>, extra: &[&str]) -> Output {
    let mut args = vec!["--quiet"];
    args.extend(extra);
    enhance_loud(dir, &args)
}

/// [`enhance_in`] without `--quiet`: the per-file lines and bars shown.
fn enhance_loud(dir: Option<&Path>, extra: &[&str]) -> Output {
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_pgrf"));
    cmd.args(["enhance", "--model", "builtin:spc", "--noise", "K=1,read=4"])
        .args(["--ratio", "10"])
        .args(extra);
    if let Some(d) = dir {
        cmd.current_dir(d);
    }
    cmd.output().expect("run pgrf")
}

fn ok(r: &Output) {
    assert!(
        r.status.success(),
        "exit {:?}: {}",
        r.status.code(),
        String::from_utf8_lossy(&r.stderr)
    );
}

fn names_in(d: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// The manifest's lines that parse, and how many do not.
fn manifest(path: &Path) -> (Vec<Value>, usize) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut torn = 0;
    let mut lines = Vec::new();
    for l in text.lines() {
        match serde_json::from_str::<Value>(l) {
            Ok(v) => lines.push(v),
            Err(_) => torn += 1,
        }
    }
    (lines, torn)
}

fn file_name(v: &Value, key: &str) -> String {
    Path::new(v[key].as_str().unwrap())
        .file_name()
        .unwrap()
        .to_string_lossy()
        .into_owned()
}

#[test]
fn shards_are_disjoint_cover_every_input_and_match_one_whole_run() {
    let d = scratch("shards");
    charts(&d.join("in"), 7);
    let all = d.join("all");
    ok(&enhance(&["-o", s(&all), s(&d.join("in")), "--png"]));
    let outputs = names_in(&all);
    assert_eq!(outputs.len(), 14, "{outputs:?}");

    // A second whole run writes the same bytes: nothing depends on the
    // time, the process or the run.
    let again = d.join("again");
    ok(&enhance(&["-o", s(&again), s(&d.join("in")), "--png"]));

    let sharded = d.join("sharded");
    let mut taken: Vec<String> = Vec::new();
    for i in 0..3 {
        let m = d.join(format!("shard{i}.jsonl"));
        let shard = format!("{i}/3");
        ok(&enhance(&[
            "-o",
            s(&sharded),
            s(&d.join("in")),
            "--shard",
            &shard,
            "--manifest",
            s(&m),
            "--png",
        ]));
        let (lines, torn) = manifest(&m);
        assert_eq!(torn, 0);
        // Sorted c0..c6 counted from 0: shard 0 takes c0 c3 c6, 1 c1 c4, 2 c2 c5.
        assert_eq!(lines.len(), [3, 2, 2][i], "shard {i}: {lines:?}");
        for l in &lines {
            assert_eq!(l["status"], "done");
            assert_eq!(l["shard"], shard.as_str());
            let name = file_name(l, "input");
            let k: usize = name[1..name.len() - 4].parse().unwrap();
            assert_eq!(k % 3, i, "{name} is not shard {i}'s");
            taken.push(name);
        }
    }
    taken.sort();
    taken.dedup();
    assert_eq!(
        taken.len(),
        7,
        "every input in exactly one shard: {taken:?}"
    );
    assert_eq!(names_in(&sharded), outputs);
    for name in &outputs {
        let want = std::fs::read(all.join(name)).unwrap();
        assert_eq!(
            std::fs::read(again.join(name)).unwrap(),
            want,
            "{name}: runs differ"
        );
        assert_eq!(
            std::fs::read(sharded.join(name)).unwrap(),
            want,
            "{name}: shard differs"
        );
    }
}

/// The flow model draws its start noise from `--seed` alone, not from a
/// file's place in the batch: a shard writes what the whole run writes.
#[test]
fn the_flow_model_writes_the_same_bytes_in_any_shard() {
    let d = scratch("flow");
    let inputs = d.join("in");
    charts(&inputs, 3);
    let run = |out: &Path, shard: Option<&str>| {
        let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_pgrf"));
        cmd.args([
            "enhance",
            "--model",
            "builtin:pgrf",
            "--noise",
            "K=1,read=4",
        ])
        .args([
            "--ratio",
            "10",
            "--seed",
            "5",
            "--quiet",
            "-o",
            s(out),
            s(&inputs),
        ]);
        if let Some(sh) = shard {
            cmd.args(["--shard", sh]);
        }
        ok(&cmd.arg("--png").output().unwrap());
    };
    run(&d.join("all"), None);
    run(&d.join("sharded"), Some("0/2"));
    run(&d.join("sharded"), Some("1/2"));
    let names = names_in(&d.join("all"));
    assert_eq!(names.len(), 6);
    assert_eq!(names_in(&d.join("sharded")), names);
    for n in &names {
        let a = std::fs::read(d.join("all").join(n)).unwrap();
        assert_eq!(std::fs::read(d.join("sharded").join(n)).unwrap(), a, "{n}");
    }
}

#[test]
fn skip_existing_keeps_whole_outputs_and_redoes_cut_ones() {
    let d = scratch("skip");
    let inputs = d.join("in");
    charts(&inputs, 3);
    let out = d.join("out");
    let args = ["-o", s(&out), s(&inputs), "--png"];
    ok(&enhance(&args));
    let bytes = |n: &str| std::fs::read(out.join(n)).unwrap();
    let (a, b, c_png) = (bytes("c0.dng"), bytes("c1.dng"), bytes("c2.png"));
    // c0 whole, dated an hour back (a rewrite would date it now); c1's DNG
    // cut in half; c2's preview cut short by 20 bytes.
    let past = SystemTime::now() - Duration::from_secs(3600);
    for n in ["c0.dng", "c0.png"] {
        let f = std::fs::File::options()
            .write(true)
            .open(out.join(n))
            .unwrap();
        f.set_modified(past).unwrap();
    }
    std::fs::write(out.join("c1.dng"), &b[..b.len() / 2]).unwrap();
    std::fs::write(out.join("c2.png"), &c_png[..c_png.len() - 20]).unwrap();

    let m = d.join("m.jsonl");
    let again = [&args[..], &["--skip-existing", "--manifest", s(&m)]].concat();
    ok(&enhance(&again));
    let mtime = |n: &str| std::fs::metadata(out.join(n)).unwrap().modified().unwrap();
    assert_eq!(mtime("c0.dng"), past, "a whole output is not rewritten");
    assert_eq!(mtime("c0.png"), past);
    assert_eq!(bytes("c0.dng"), a);
    assert_eq!(
        bytes("c1.dng"),
        b,
        "the cut DNG is redone, to the same bytes"
    );
    assert_eq!(bytes("c2.png"), c_png, "the cut preview is redone");
    let (lines, _) = manifest(&m);
    let status: Vec<(String, &str)> = (lines.iter())
        .map(|l| (file_name(l, "input"), l["status"].as_str().unwrap()))
        .collect();
    assert_eq!(
        status,
        [
            ("c0.dng".into(), "skipped"),
            ("c1.dng".into(), "done"),
            ("c2.dng".into(), "done")
        ]
    );
    assert_eq!(lines[0]["noise"], Value::Null);
    assert_eq!(lines[1]["noise"], "K 1.0000 DN/e-, read 4.000 DN (--noise)");
    assert_eq!(
        names_in(&out).len(),
        6,
        "no part file left: {:?}",
        names_in(&out)
    );
}

#[test]
fn from_list_skips_comments_and_blank_lines_and_reads_paths_from_the_current_folder() {
    let d = scratch("list");
    charts(&d.join("in"), 4);
    // Relative to the folder pgrf runs in, as `find . -name '*.dng'` writes
    // them; one more input on the command line, one named twice.
    std::fs::write(
        d.join("night.txt"),
        "# tonight's frames\n\n./in/c2.dng\n  in/c0.dng  \n   # not this one: in/c1.dng\n\nin/c2.dng\n",
    )
    .unwrap();
    let r = enhance_in(
        Some(&d),
        &["--from-list", "night.txt", "in/c3.dng", "-o", "out"],
    );
    ok(&r);
    assert_eq!(names_in(&d.join("out")), ["c0.dng", "c2.dng", "c3.dng"]);

    // A listed file that does not exist: one line naming the list and the
    // line, before any work (no output folder made).
    std::fs::write(d.join("bad.txt"), "in/c0.dng\n# fine so far\nin/c9.dng\n").unwrap();
    let r = enhance_in(Some(&d), &["--from-list", "bad.txt", "-o", "out2"]);
    let e = one_line_error(&r);
    assert!(
        e.contains("bad.txt line 3") && e.contains("in/c9.dng"),
        "{e}"
    );
    assert!(!d.join("out2").exists());
    let e = one_line_error(&enhance_in(
        Some(&d),
        &["--from-list", "nope.txt", "-o", "out2"],
    ));
    assert!(e.contains("--from-list nope.txt"), "{e}");
    // A list of comments only, and no other input.
    std::fs::write(d.join("empty.txt"), "# nothing tonight\n\n").unwrap();
    let e = one_line_error(&enhance_in(
        Some(&d),
        &["--from-list", "empty.txt", "-o", "out2"],
    ));
    assert!(e.contains("no inputs"), "{e}");
}

#[test]
fn a_bad_file_fails_alone_and_the_batch_exits_3() {
    let d = scratch("bad-file");
    let inputs = d.join("in");
    charts(&inputs, 3);
    std::fs::write(inputs.join("c1b.dng"), b"not a raw file").unwrap();
    let out = d.join("out");
    let m = d.join("m.jsonl");
    let r = enhance(&["-o", s(&out), s(&inputs), "--manifest", s(&m)]);
    let err = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(3), "{err}");
    let errors: Vec<&str> = err
        .lines()
        .filter(|l| l.starts_with("pgrf: error:"))
        .collect();
    assert_eq!(errors.len(), 1, "{err}");
    assert_eq!(
        errors[0],
        format!(
            "pgrf: error: 1 of 4 files failed: {}",
            inputs.join("c1b.dng").display()
        )
    );
    assert_eq!(names_in(&out), ["c0.dng", "c1.dng", "c2.dng"]);
    let (lines, _) = manifest(&m);
    let failed: Vec<&Value> = lines.iter().filter(|l| l["status"] == "failed").collect();
    assert_eq!((lines.len(), failed.len()), (4, 1));
    assert_eq!(file_name(failed[0], "input"), "c1b.dng");
    assert!(failed[0]["error"].as_str().unwrap().contains("c1b.dng"));
    assert_eq!(failed[0]["noise"], Value::Null);
    for l in lines.iter().filter(|l| l["status"] == "done") {
        assert_eq!(l["error"], Value::Null);
    }

    // Without --quiet each file says what became of it, the failure among
    // them, and the summary is still the only error line.
    let loud = enhance_loud(None, &["-o", s(&d.join("out2")), s(&inputs)]);
    let err = String::from_utf8_lossy(&loud.stderr);
    assert_eq!(loud.status.code(), Some(3), "{err}");
    assert_eq!(
        err.lines().filter(|l| l.starts_with("wrote ")).count(),
        3,
        "{err}"
    );
    assert_eq!(
        err.lines().filter(|l| l.starts_with("failed ")).count(),
        1,
        "{err}"
    );
    assert_eq!(
        err.lines()
            .filter(|l| l.starts_with("pgrf: error:"))
            .count(),
        1
    );
}

#[test]
fn a_manifest_cut_short_by_a_kill_stays_readable_line_by_line() {
    let d = scratch("manifest");
    charts(&d.join("in"), 2);
    let m = d.join("m.jsonl");
    // One whole line, then one a SIGKILL cut in the middle.
    std::fs::write(
        &m,
        "{\"input\":\"x.dng\",\"status\":\"done\"}\n{\"input\":\"y.dn",
    )
    .unwrap();
    ok(&enhance(&[
        "-o",
        s(&d.join("out")),
        s(&d.join("in")),
        "--manifest",
        s(&m),
    ]));
    let text = std::fs::read_to_string(&m).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 4, "{text}");
    assert_eq!(
        lines[1], "{\"input\":\"y.dn",
        "the cut line stays alone on its line"
    );
    let (parsed, torn) = manifest(&m);
    assert_eq!((parsed.len(), torn), (3, 1));
    assert!(text.ends_with('\n'));
    for l in &parsed[1..] {
        assert_eq!(l["status"], "done");
        let keys: Vec<&str> = l.as_object().unwrap().keys().map(|k| k.as_str()).collect();
        let mut want = [
            "input", "output", "png", "status", "seconds", "noise", "error", "shard",
        ];
        want.sort();
        let mut keys = keys;
        keys.sort();
        assert_eq!(keys, want);
    }
}

#[test]
fn bad_shards_and_manifests_are_one_line_errors_and_an_empty_shard_is_no_error() {
    let d = scratch("bad-shard");
    let inputs = d.join("in");
    charts(&inputs, 2);
    let out = d.join("out");
    for (shard, says) in [
        ("4/4", "below N"),
        ("1/0", "at least 1"),
        ("x/y", "expected I/N"),
        ("3", "expected I/N"),
        ("-1/3", "expected I/N"),
    ] {
        let e = one_line_error(&enhance(&["-o", s(&out), s(&inputs), "--shard", shard]));
        assert!(
            e.contains(&format!("--shard {shard}")) && e.contains(says),
            "{e}"
        );
    }
    let e = one_line_error(&enhance(&[
        "-o",
        s(&out),
        s(&inputs),
        "--manifest",
        s(&inputs.join("c0.dng")),
    ]));
    assert!(e.contains("--manifest") && e.contains("input"), "{e}");
    let e = one_line_error(&enhance(&[
        "-o",
        s(&out),
        s(&inputs),
        "--manifest",
        s(&inputs.join("m.jsonl")),
    ]));
    assert!(e.contains("inside the input folder"), "{e}");
    assert!(!inputs.join("m.jsonl").exists());

    // Two inputs, shard 5 of 8: nothing to do, exit 0, nothing written.
    let r = enhance_in(None, &["-o", s(&out), s(&inputs), "--shard", "5/8"]);
    ok(&r);
    assert!(!out.exists() || names_in(&out).is_empty());
    let loud = enhance_loud(None, &["-o", s(&out), s(&inputs), "--shard", "5/8"]);
    ok(&loud);
    let err = String::from_utf8_lossy(&loud.stderr);
    assert!(err.contains("shard 5/8: nothing to do"), "{err}");
}

/// tools/load_fault.py at CI scale: 40 files, 4 shards at once, 6 SIGKILLs
/// at seeded random moments, restarts until each shard exits 0; the tool
/// checks outputs (one each, nothing else, bit-identical to one whole run)
/// and manifests.
#[test]
fn shards_killed_and_restarted_finish_the_batch_as_one_run_would() {
    let tool = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tools/load_fault.py");
    let r = std::process::Command::new("python3")
        .arg(&tool)
        .args([
            "--files", "40", "--shards", "4", "--kills", "6", "--seed", "7",
        ])
        .args(["--pgrf", env!("CARGO_BIN_EXE_pgrf")])
        .output()
        .expect("run python3 tools/load_fault.py");
    let text = String::from_utf8_lossy(&r.stdout);
    assert!(
        r.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&r.stderr)
    );
    assert!(text.contains("load_fault: all checks passed"), "{text}");
    // Kills come at random moments; a shard may finish before one is due,
    // but most land (6 of 6 on the machine this was written on).
    let landed: usize = (text.split(" at once, ").nth(1))
        .and_then(|t| t.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or(0);
    assert!(landed >= 1, "{text}");
}

/// The offset and length of the first tile of a little-endian DNG's first
/// IFD (tags 324 TileOffsets and 325 TileByteCounts).
fn first_tile(b: &[u8]) -> (usize, usize) {
    let u16_at = |at: usize| u16::from_le_bytes([b[at], b[at + 1]]) as usize;
    let u32_at = |at: usize| u32::from_le_bytes(b[at..at + 4].try_into().unwrap()) as usize;
    assert_eq!(&b[..2], b"II");
    let ifd = u32_at(4);
    let first = |tag: usize| {
        (0..u16_at(ifd))
            .map(|i| ifd + 2 + 12 * i)
            .find(|&e| u16_at(e) == tag)
            .map(|e| {
                // One tile: the value itself; several: a pointer to LONGs.
                if u32_at(e + 4) == 1 {
                    u32_at(e + 8)
                } else {
                    u32_at(u32_at(e + 8))
                }
            })
            .expect("a tiled DNG")
    };
    (first(324), first(325))
}

/// Issue 53, item 5: a DNG damaged inside its compressed tile data, whose
/// structure still decodes (to wrong pixels), is redone by
/// `--skip-existing`: its pixels no longer match the digest it was written
/// with. The whole file is left alone.
#[test]
fn skip_existing_redoes_a_dng_damaged_inside_its_tiles() {
    let d = scratch("tiles");
    let inputs = charts(&d.join("in"), 1);
    let out = d.join("c0.dng");
    let args = [s(&inputs[0]), "-o", s(&out), "--skip-existing"];
    ok(&enhance(&args));
    let whole = std::fs::read(&out).unwrap();
    let pixels = pgrf_raw::decode_file(&out, &Default::default())
        .unwrap()
        .mosaic;
    let (tile, len) = first_tile(&whole);
    // A byte in the tile's entropy-coded data that still decodes, to other
    // pixels (a flip can also break the decoding, which was caught before).
    let damaged = (1..16)
        .map(|k| tile + len * k / 16)
        .find_map(|at| {
            let mut b = whole.clone();
            b[at] ^= 0x08;
            std::fs::write(&out, &b).unwrap();
            let f = pgrf_raw::decode_file(&out, &Default::default()).ok()?;
            (f.mosaic != pixels).then_some(b)
        })
        .expect("a flipped byte that decodes to other pixels");
    assert!(damaged != whole);
    let m = d.join("m.jsonl");
    ok(&enhance(&[&args[..], &["--manifest", s(&m)]].concat()));
    assert!(
        std::fs::read(&out).unwrap() == whole,
        "the damaged DNG is redone"
    );
    ok(&enhance(&[&args[..], &["--manifest", s(&m)]].concat()));
    let (lines, _) = manifest(&m);
    let status: Vec<&str> = lines
        .iter()
        .map(|l| l["status"].as_str().unwrap())
        .collect();
    assert_eq!(status, ["done", "skipped"]);
}
