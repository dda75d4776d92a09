//! No command writes over one of its inputs, into a folder it was given
//! as a file, or twice to one file; and a refused run writes nothing.

mod common;
use common::{one_line_error, pgrf, s, scratch};

#[test]
fn outputs_never_name_inputs_and_refused_runs_write_nothing() {
    let d = scratch("outputs", "guard");
    let dng = d.join("in.dng");
    common::chart(&dng, 128, 96);
    let before = std::fs::read(&dng).unwrap();
    let png = d.join("p.png");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["preview", s(&dng), "-o", s(&dng)], "is the input"),
        (vec!["convert", s(&dng), "-o", s(&dng)], "is the input"),
        (
            vec!["synth", s(&dng), "--profile", "sony-a7s2", "-o", s(&dng)],
            "is the input",
        ),
        (
            vec![
                "synth",
                s(&dng),
                "--profile",
                "sony-a7s2",
                "-o",
                s(&png),
                "--png",
                s(&png),
            ],
            "both name",
        ),
        (
            vec![
                "synth",
                s(&dng),
                "--profile",
                "sony-a7s2",
                "-o",
                s(&png),
                "--png-gain",
                "NaN",
            ],
            "--png-gain",
        ),
        (vec!["preview", s(&dng), "-o", s(&d)], "is a folder"),
        (
            vec![
                "train",
                "spc",
                "--data",
                "procedural",
                "--steps",
                "1",
                "-o",
                s(&d),
            ],
            "is a folder",
        ),
        (
            vec![
                "train",
                "spc",
                "--data",
                "procedural",
                "--steps",
                "1",
                "--calib",
                s(&dng),
                "-o",
                s(&dng),
            ],
            "is the input",
        ),
    ];
    for (args, needle) in cases {
        let e = one_line_error(&pgrf(&args));
        assert!(e.contains(needle), "{args:?}: {e}");
    }
    assert_eq!(
        std::fs::read(&dng).unwrap(),
        before,
        "the input was touched"
    );
    let names: Vec<_> = std::fs::read_dir(&d)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, ["in.dng"], "a refused run left files");
    std::fs::remove_dir_all(&d).unwrap();
}
