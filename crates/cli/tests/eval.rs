//! `pgrf make-dataset` + `pgrf eval` end to end: a miniature ELD/SID folder
//! made by pgrf is walked by eval with tiny seeded networks; the table has
//! one row per ratio with the right image counts, the CSV one line per image
//! and method, and errors are one line naming what is wrong.

mod common;
use common::{one_line_error, pgrf, s};

use std::path::{Path, PathBuf};
use std::process::Output;

fn scratch(name: &str) -> PathBuf {
    common::scratch("eval", name)
}

fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Tiny networks with seeded weights: the plumbing is under test.
fn model(dir: &Path, flow: bool) -> PathBuf {
    common::tiny_model(dir, flow, None, 5)
}

/// (ratio label, images, [(psnr, ssim) per method]): one row of the stdout table.
type TableRow = (String, usize, Vec<(f64, f64)>);

fn table(stdout: &str) -> Vec<TableRow> {
    stdout
        .lines()
        .filter(|l| l.starts_with('x'))
        .map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            let cells = f[2..]
                .chunks(3)
                .map(|c| (c[0].parse().unwrap(), c[2].parse().unwrap()))
                .collect();
            (f[0].to_string(), f[1].parse().unwrap(), cells)
        })
        .collect()
}

#[test]
fn eld_miniature_end_to_end() {
    let d = scratch("eld");
    let root = d.join("ELD");
    ok(&pgrf(&[
        "make-dataset",
        "--layout",
        "eld",
        "-o",
        s(&root),
        "--scenes",
        "2",
        "--size",
        "128x128",
    ]));
    let scene = root.join("SonyA7S2").join("scene-2");
    let mut names: Vec<String> = std::fs::read_dir(&scene)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    let want: Vec<String> = (1..=16).map(|f| format!("IMG_{f:04}.dng")).collect();
    assert_eq!(names, want);

    let (spc, flow) = (model(&d, false), model(&d, true));
    let (csv, md, png) = (
        d.join("per_image.csv"),
        d.join("table.md"),
        d.join("worst.png"),
    );
    let out = ok(&pgrf(&[
        "eval",
        "--protocol",
        "eld",
        "--root",
        s(&root),
        "--scenes",
        "1-2",
        "--model",
        s(&spc),
        "--model",
        s(&flow),
        "--csv",
        s(&csv),
        "--markdown",
        s(&md),
        "--worst",
        s(&png),
        "--worst-count",
        "3",
    ]));
    assert!(out.starts_with("protocol eld:"), "{out}");
    assert!(
        out.contains("frames 4,9,14") && out.contains("illuminance correction on"),
        "{out}"
    );
    let t = table(&out);
    assert_eq!(t.len(), 2, "{out}");
    assert_eq!((t[0].0.as_str(), t[0].1), ("x100", 6));
    assert_eq!((t[1].0.as_str(), t[1].1), ("x200", 6));
    for (_, _, cells) in &t {
        assert_eq!(cells.len(), 3, "{out}");
        assert!(cells
            .iter()
            .all(|(p, s)| p.is_finite() && *p > 0.0 && (0.0..=1.0).contains(s)));
    }
    assert!(out.contains("noisy input") && out.contains("spc") && out.contains("flow"));
    assert!(
        out.contains("white 16383") && out.contains("res_in"),
        "{out}"
    );

    let text = std::fs::read_to_string(&csv).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(
        lines[0],
        "protocol,id,ratio_group,ratio,noisy,reference,method,psnr,ssim,gain"
    );
    assert_eq!(lines.len(), 1 + 12 * 3);
    // Frame 9 of scene 1 is paired with reference 11 at ratio 100 (ISO x exposure).
    let row = lines
        .iter()
        .find(|l| l.starts_with("eld,scene-1/IMG_0009,100,100,") && l.contains(",spc,"))
        .unwrap_or_else(|| panic!("{text}"));
    assert!(row.contains("scene-1/IMG_0011.dng"), "{row}");
    // The noisy input is measured without the correction (ELD's res_in), models with it.
    for l in &lines[1..] {
        let gain = l.rsplit(',').next().unwrap();
        assert_eq!(gain.is_empty(), l.contains(",noisy input,"), "{l}");
    }
    let frames: std::collections::BTreeSet<&str> = lines[1..]
        .iter()
        .map(|l| l.split(',').nth(1).unwrap())
        .collect();
    let want: std::collections::BTreeSet<String> = [1, 2]
        .iter()
        .flat_map(|s| [4, 9, 14, 5, 10, 15].map(|f| format!("scene-{s}/IMG_{f:04}")))
        .collect();
    assert_eq!(frames, want.iter().map(String::as_str).collect());
    let md = std::fs::read_to_string(&md).unwrap();
    assert!(
        md.contains("| Ratio | Images |") && md.contains("| x200 | 6 |"),
        "{md}"
    );
    let img = image::open(&png).unwrap();
    // 3 worst images x (noisy, spc, flow, reference), 64x64 packed -> 128 px
    // tiles, 8 px apart, each under a 30 px caption.
    assert_eq!(
        (img.width(), img.height()),
        (4 * 128 + 3 * 8, 3 * (128 + 30) + 2 * 8)
    );

    // Without the baseline: one column per model.
    let out = ok(&pgrf(&[
        "eval",
        "--protocol",
        "eld",
        "--root",
        s(&root),
        "--scenes",
        "1",
        "--model",
        s(&spc),
        "--noise-baseline",
        "none",
        "--illuminance-correct",
        "off",
        "-q",
    ]));
    assert!(out.contains("illuminance correction off"), "{out}");
    let t = table(&out);
    assert_eq!(
        t.iter().map(|r| (r.1, r.2.len())).collect::<Vec<_>>(),
        vec![(3, 1), (3, 1)]
    );

    // The default scenes 1-10 need scene-3.
    let e = one_line_error(&pgrf(&[
        "eval",
        "--protocol",
        "eld",
        "--root",
        s(&root),
        "--model",
        s(&spc),
    ]));
    assert!(e.contains("scene-3"), "{e}");
    // A missing frame: one line naming the file.
    let gone = scene.join("IMG_0014.dng");
    std::fs::remove_file(&gone).unwrap();
    let e = one_line_error(&pgrf(&[
        "eval",
        "--protocol",
        "eld",
        "--root",
        s(&root),
        "--scenes",
        "1-2",
        "--model",
        s(&spc),
    ]));
    assert!(e.contains("IMG_0014.ARW") && e.contains("scene-2"), "{e}");
    // A model file of the wrong kind.
    let e = one_line_error(&pgrf(&[
        "eval",
        "--protocol",
        "eld",
        "--root",
        s(&root),
        "--scenes",
        "1",
        "--model",
        s(&scene.join("IMG_0001.dng")),
    ]));
    assert!(e.contains("--model"), "{e}");
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn sid_miniature_and_pair_list() {
    let d = scratch("sid");
    let root = d.join("SID");
    ok(&pgrf(&[
        "make-dataset",
        "--layout",
        "sid",
        "-o",
        s(&root),
        "--scenes",
        "2",
        "--size",
        "96x64",
        "--seed",
        "3",
    ]));
    let spc = model(&d, false);
    let csv = d.join("sid.csv");
    let out = ok(&pgrf(&[
        "eval",
        "--protocol",
        "sid",
        "--root",
        s(&root),
        "--model",
        s(&spc),
        "--csv",
        s(&csv),
    ]));
    assert!(
        out.contains("centre 512x512") && out.contains("excluded"),
        "{out}"
    );
    let t = table(&out);
    let rows: Vec<(&str, usize)> = t.iter().map(|r| (r.0.as_str(), r.1)).collect();
    assert_eq!(rows, vec![("x100", 2), ("x250", 2), ("x300", 2)], "{out}");
    assert!(t.iter().all(|r| r.2.iter().all(|c| c.0.is_finite())));
    // The worst-images PNG defaults to a name next to the CSV.
    assert!(d.join("sid_worst.png").is_file());
    // A smaller crop: input and reference cut before the network (16 packed
    // pixels -> 32-pixel previews: noisy, spc, reference).
    let png = d.join("crop.png");
    let out = ok(&pgrf(&[
        "eval",
        "--protocol",
        "sid",
        "--root",
        s(&root),
        "--model",
        s(&spc),
        "--crop",
        "16",
        "--worst",
        s(&png),
        "--worst-count",
        "1",
        "-q",
    ]));
    assert!(out.contains("centre 16x16"), "{out}");
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (3 * 32 + 2 * 8, 32 + 30));

    // A pair list of the user's own: ratio given, and from EXIF.
    let short = root.join("Sony/short");
    let long = root.join("Sony/long");
    let list = d.join("pairs.csv");
    std::fs::write(
        &list,
        format!(
            "noisy,reference,ratio\n{},{},100\n{},{},\n",
            s(&short.join("10001_00_0.1s.dng")),
            s(&long.join("10001_00_10s.dng")),
            s(&short.join("10002_00_0.04s.dng")),
            s(&long.join("10002_00_10s.dng")),
        ),
    )
    .unwrap();
    let out = ok(&pgrf(&[
        "eval",
        "--protocol",
        "pairs",
        "--root",
        s(&list),
        "--model",
        s(&spc),
    ]));
    let t = table(&out);
    assert_eq!(
        t.iter().map(|r| (r.0.as_str(), r.1)).collect::<Vec<_>>(),
        vec![("x0", 1), ("x100", 1)],
        "{out}"
    );
    std::fs::write(&list, "noisy,reference,ratio\n").unwrap();
    let e = one_line_error(&pgrf(&[
        "eval",
        "--protocol",
        "pairs",
        "--root",
        s(&list),
        "--model",
        s(&spc),
    ]));
    assert!(e.contains("no pairs"), "{e}");
    let e = one_line_error(&pgrf(&[
        "eval",
        "--protocol",
        "sid",
        "--root",
        s(&d.join("nope")),
        "--model",
        s(&spc),
    ]));
    assert!(e.contains("no such folder"), "{e}");
    let _ = std::fs::remove_dir_all(&d);
}

/// The walker's frame choice and ratio rule against ELD's published frame
/// table (skipped without ../shared/data).
#[test]
#[cfg_attr(not(shared_data), ignore = "needs ../shared/data")]
fn eld_frame_table_gives_the_walker_ratios() {
    use pgrf_eval::dataset::eld;
    let path = pgrf_core::shared_data_dir()
        .expect("../shared/data")
        .join("protocols/ELD_SonyA7S2_frames.json");
    let text = std::fs::read_to_string(&path).unwrap();
    let rows: Vec<serde_json::Value> = serde_json::from_str(&text).unwrap();
    let get = |scene: u64, frame: u32| {
        let r = rows
            .iter()
            .find(|r| r["scene"] == scene && r["frame"] == frame)
            .unwrap();
        (
            r["ISO"].as_f64().unwrap(),
            r["ExposureTime_s"].as_f64().unwrap(),
        )
    };
    for scene in 1..=10u64 {
        for (want, frames) in [(100.0, eld::X100), (200.0, eld::X200)] {
            for f in frames {
                let (i, t) = get(scene, f);
                let (ri, rt) = get(scene, eld::reference_for(f));
                let ratio = ri * rt / (i * t);
                assert!(
                    (ratio - want).abs() < 1e-6,
                    "scene {scene} frame {f}: {ratio}"
                );
                assert_eq!(i as u32, eld::FRAME_TABLE[f as usize - 1].0);
            }
        }
        for r in eld::REFERENCES {
            assert_eq!(get(scene, r).0, 100.0);
        }
    }
}
