//! Counts and frame sizes against the memory there is (issue 37, finding
//! 2): each case below once aborted (or ended in an internal error) after
//! asking for gigabytes; now each is refused in one line with the figures,
//! under the 2 GB address-space limit the hostile campaign runs with.

mod common;
use common::{s, scratch};
use std::io::{Seek, SeekFrom, Write};
use std::path::Path;
use std::process::{Command, Output};

/// `pgrf ARGS` with its address space capped at 2 GiB (`ulimit -v`), as
/// tools/hostile_campaign.py runs it.
fn pgrf_capped(args: &[&str]) -> Output {
    Command::new("sh")
        .arg("-c")
        .arg("ulimit -v 2097152 && exec \"$0\" \"$@\"")
        .arg(env!("CARGO_BIN_EXE_pgrf"))
        .args(args)
        .output()
        .expect("run pgrf under ulimit")
}

/// The run was refused in one `pgrf: error:` line (exit 1), returned.
fn refused(out: &Output) -> String {
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(out.status.code(), Some(1), "stderr: {err}");
    assert_eq!(lines.len(), 1, "expected one line: {err}");
    assert!(lines[0].starts_with("pgrf: error: "), "{err}");
    err
}

/// A FITS file of `w` x `h` samples of `bitpix` bits, all zero, written
/// sparse (its data take no disk); `bayer` adds BAYERPAT = 'RGGB'.
fn sparse_fits(path: &Path, w: u64, h: u64, bitpix: i32, bayer: bool) {
    let mut cards = vec![
        format!("SIMPLE  = {:>20}", "T"),
        format!("BITPIX  = {bitpix:>20}"),
        format!("NAXIS   = {:>20}", 2),
        format!("NAXIS1  = {w:>20}"),
        format!("NAXIS2  = {h:>20}"),
    ];
    if bayer {
        cards.push("BAYERPAT= 'RGGB'".into());
    }
    cards.push("END".into());
    let mut header: String = cards.iter().map(|c| format!("{c:<80}")).collect();
    while !header.len().is_multiple_of(2880) {
        header.push(' ');
    }
    let data = w * h * (bitpix.unsigned_abs() as u64 / 8);
    let total = (header.len() as u64 + data).div_ceil(2880) * 2880;
    let mut f = std::fs::File::create(path).unwrap();
    f.write_all(header.as_bytes()).unwrap();
    f.seek(SeekFrom::Start(total - 1)).unwrap();
    f.write_all(&[0]).unwrap();
}

#[test]
fn fits_frames_beyond_600_mp_or_the_memory_are_refused_before_decoding() {
    let d = scratch("memory", "fits");
    // 720 MP: refused by size alone, from the header (the data are not
    // even there).
    let huge = d.join("huge.fits");
    let mut f = std::fs::File::create(&huge).unwrap();
    let cards = [
        "SIMPLE  =                    T",
        "BITPIX  =                    8",
        "NAXIS   =                    2",
        "NAXIS1  =                30000",
        "NAXIS2  =                24000",
        "END",
    ];
    let mut header: String = cards.iter().map(|c| format!("{c:<80}")).collect();
    header.push_str(&" ".repeat(2880 - header.len()));
    f.write_all(header.as_bytes()).unwrap();
    drop(f);
    for cmd in ["info", "preview", "convert"] {
        let mut args = vec![cmd, s(&huge)];
        let out = d.join(if cmd == "preview" { "p.png" } else { "c.dng" });
        if cmd != "info" {
            args.extend(["-o", s(&out)]);
        }
        let e = refused(&pgrf_capped(&args));
        assert!(
            e.contains("30000 x 24000 image (720 megapixels)"),
            "{cmd}: {e}"
        );
    }
    // 500 MP of 8-bit samples (500 MB, sparse): within 600 MP, but its
    // decode needs 6 B/px, 2.8 GiB, more than the 2 GiB cap leaves.
    let big = d.join("big.fits");
    sparse_fits(&big, 25000, 20000, 8, false);
    let png = d.join("p.png");
    for args in [
        vec!["info", s(&big)],
        vec!["preview", "--half", s(&big), "-o", s(&png)],
    ] {
        let e = refused(&pgrf_capped(&args));
        assert!(
            e.contains("decoding its 25000 x 20000 frame (500 MP) needs about 2.8 GiB of memory"),
            "{e}"
        );
    }
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn flow_samples_are_bounded_and_their_start_fields_counted() {
    let d = scratch("memory", "samples");
    // A 12 MP Bayer frame (24 MB, sparse).
    let frame = d.join("frame.fits");
    sparse_fits(&frame, 4000, 3000, 16, true);
    let out = d.join("e.dng");
    let enhance = |samples: &str| {
        pgrf_capped(&[
            "enhance",
            s(&frame),
            "--model",
            "builtin:pgrf",
            "--ratio",
            "20",
            "--noise",
            "K=1,read=4",
            "--samples",
            samples,
            "-o",
            s(&out),
        ])
    };
    let e = refused(&enhance("1000000000"));
    assert!(
        e.contains("--samples must be from 1 to 64, got 1000000000"),
        "{e}"
    );
    // 64 start fields of 12 MP at 4 B each are 3 GiB: refused with the
    // figures and the flag to change, before any is made.
    let e = refused(&enhance("64"));
    assert!(
        e.contains("restoring its 4000 x 3000 frame (12 MP) with --samples 64 needs about")
            && e.contains("give fewer --samples"),
        "{e}"
    );
    assert!(!out.exists());
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn training_counts_are_bounded_by_memory_and_threads() {
    let d = scratch("memory", "train");
    let out = d.join("m.safetensors");
    let train = |extra: &[&str]| {
        let mut args = vec!["train", "denoiser", "-o", s(&out)];
        if !extra.contains(&"--steps") {
            args.extend(["--steps", "1"]);
        }
        args.extend(extra);
        pgrf_capped(&args)
    };
    let e = refused(&train(&["--val-pairs", "1000000000"]));
    assert!(
        e.contains("1000000000 validation pairs of 256 needs about")
            && e.contains("GiB is available"),
        "{e}"
    );
    let e = refused(&train(&["--batch", "1000000000"]));
    assert!(e.contains("--batch 1000000000"), "{e}");
    for w in ["0", "65", "1000000000"] {
        let e = refused(&train(&["--workers", w]));
        assert!(e.contains(&format!("1 to 64, got {w}")), "{e}");
    }
    // Steps beyond 10^9 are a usage error (exit 2), named by clap.
    let o = train(&["--steps", "18446744073709551615"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("is not in 0..=1000000000"));
    assert!(!out.exists());
    std::fs::remove_dir_all(&d).unwrap();
}
