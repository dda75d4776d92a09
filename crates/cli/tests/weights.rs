//! `pgrf import-weights` / `export-weights` through the binary: a published
//! checkpoint's shape in, a pgrf weight file out that `enhance` runs like
//! its own; bad files refused in one line with nothing written.

mod common;

use common::{one_line_error, pgrf, s, scratch};
use std::path::{Path, PathBuf};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../nn/tests/data/sid_unet")
        .join(name)
}

#[test]
fn an_imported_checkpoint_enhances_and_exports() {
    let dir = scratch("weights", "roundtrip");
    let model = dir.join("eld.safetensors");
    let r = pgrf(&[
        "import-weights",
        s(&fixture("eld_legacy.pth")),
        "--from",
        "eld",
        "-o",
        s(&model),
    ]);
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{err}");
    assert!(
        err.contains("under 'netG.'") && err.contains("--white 16383"),
        "{err}"
    );
    // pgrf's own commands take it like a file of their own.
    let demo = dir.join("demo");
    let r = pgrf(&["demo", "-o", s(&demo), "--size", "128x96", "--quiet"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let out = dir.join("out.dng");
    let r = pgrf(&[
        "enhance",
        s(&demo.join("noisy_x100.dng")),
        "--model",
        s(&model),
        "--ratio",
        "100",
        "-o",
        s(&out),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert!(out.exists());
    // Out to PyTorch and back: the same tensors, so the same bytes again.
    let (pth, again) = (dir.join("a.pth"), dir.join("b.pth"));
    let back = dir.join("back.safetensors");
    for args in [
        vec!["export-weights", s(&model), "-o", s(&pth)],
        vec!["import-weights", s(&pth), "-o", s(&back)],
        vec!["export-weights", s(&back), "-o", s(&again)],
    ] {
        let r = pgrf(&args);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    }
    assert!(std::fs::read(&pth).unwrap() == std::fs::read(&again).unwrap());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_checkpoints_give_one_line_and_write_nothing() {
    let dir = scratch("weights", "bad");
    let out = dir.join("x.safetensors");
    for (file, says) in [
        ("other_arch.pth", "not a UNetSeeInDark"),
        ("truncated.pth", "zip"),
        ("malicious.pth", "os.system"),
        ("non_tensor.pth", "conv10_1.bias is missing or not a tensor"),
        ("missing_key.pth", "conv10_1.bias is missing"),
        ("shape_mismatch.pth", "conv1_1.weight has shape"),
    ] {
        let r = pgrf(&["import-weights", s(&fixture(file)), "-o", s(&out)]);
        let e = one_line_error(&r);
        assert!(e.contains(says) && e.contains(file), "{file}: {e}");
        assert!(!out.exists(), "{file}: wrote {}", out.display());
    }
    let e = one_line_error(&pgrf(&[
        "import-weights",
        s(&fixture("plain.pth")),
        "--arch",
        "sr3",
        "-o",
        s(&out),
    ]));
    assert!(e.contains("--arch sr3"), "{e}");
    let e = one_line_error(&pgrf(&[
        "export-weights",
        s(&fixture("plain.pth")),
        "-o",
        s(&dir.join("y.pth")),
    ]));
    assert!(e.contains("plain.pth"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}
