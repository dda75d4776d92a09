//! darktable and RawTherapee as test clients (issue 53, item 4): they read
//! DNGs with decoders of their own (rawspeed, RawTherapee's dcraw-derived
//! one), and they are where a photographer opens pgrf's results. Each DNG
//! is rendered by `darktable-cli` (default processing, a throw-away
//! configuration and an in-memory library) and `rawtherapee-cli` (its
//! neutral profile: exposure equal, see [`render`]); the renders of
//! `convert`'s output and of `enhance`'s output at ratio 1 of a clean frame
//! match the input's within ΔE*ab 1 on the chart's six grey patches, and
//! `reduce`'s DNG opens in both at its size. Tested with darktable 4.2.1 and RawTherapee 5.9 (Debian 12's
//! packages, which `.ci/run` installs when they are missing); without them
//! the test says it skipped.
//!
//! RawTherapee 5.9 opens no raw file under about 100,000 bytes ("Error
//! loading file"), whatever its layout: pgrf's DNGs of 96 x 64 ... 600 x
//! 200 (13-90 kB) were refused, from 768 x 200 (100.6 kB) up they open, and
//! a refused 256 x 256 DNG opens once padded with zeros past 100,000 bytes
//! (measured 2026-11-28). A photograph is always larger, so `reduce`'s
//! frame here is 640 x 480.

mod common;
use common::{pgrf, s};

use std::path::{Path, PathBuf};
use std::process::Command;

/// The two photo editors.
#[derive(Clone, Copy, Debug)]
enum App {
    Darktable,
    RawTherapee,
}

fn installed(tool: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {tool}")])
        .output()
        .is_ok_and(|o| o.status.success())
}

/// `dng` rendered by `app` with its default processing, as 8-bit sRGB.
fn render(app: App, dng: &Path, work: &Path) -> image::RgbImage {
    let png = work.join(format!(
        "{}.{app:?}.png",
        dng.file_stem().unwrap().to_string_lossy()
    ));
    let out = match app {
        App::Darktable => Command::new("darktable-cli")
            .arg(dng)
            .arg(&png)
            .args(["--core", "--configdir", s(&work.join("dtconf"))])
            .args(["--library", ":memory:"])
            .output(),
        // Its neutral profile (no -d; -n: PNG; -Y: overwrite): the default
        // raw profile fits its tone curve to each image (Auto-Matched
        // Curve), so that two renders of nearly equal data differ by up to
        // 1.7 ΔE*ab (measured: a result 74 dB from its input); neutral keeps
        // the exposure equal.
        App::RawTherapee => Command::new("rawtherapee-cli")
            .env("HOME", work.join("rtconf"))
            .args(["-n", "-Y", "-o", s(&png), "-c", s(dng)])
            .output(),
    }
    .unwrap();
    assert!(
        out.status.success() && png.is_file(),
        "{app:?} failed on {}: {}",
        dng.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    image::open(&png).unwrap().to_rgb8()
}

/// CIE 1976 L*a*b* (D65) of an 8-bit sRGB pixel.
fn lab(p: [u8; 3]) -> [f64; 3] {
    let linear = p.map(|v| pgrf_raw::color::srgb_decode(v as f32 / 255.0) as f64);
    pgrf_eval::cast::lab_of_linear_srgb(linear)
}

/// Mean L*a*b* of the 41 x 41 box centred on (x, y) of the DNG's frame,
/// in a render that may be smaller than the frame by a border (RawTherapee
/// leaves out 4 pixels on each side).
fn box_lab(img: &image::RgbImage, frame: (u32, u32), (x, y): (u32, u32)) -> [f64; 3] {
    let (dx, dy) = ((frame.0 - img.width()) / 2, (frame.1 - img.height()) / 2);
    let mut sum = [0.0; 3];
    for yy in y - 20..=y + 20 {
        for xx in x - 20..=x + 20 {
            let l = lab(img.get_pixel(xx - dx, yy - dy).0);
            (0..3).for_each(|i| sum[i] += l[i] / 41.0 / 41.0);
        }
    }
    sum
}

/// ΔE*ab of each box between two renders of a frame.
fn delta_e(
    a: &image::RgbImage,
    b: &image::RgbImage,
    frame: (u32, u32),
    boxes: &[(u32, u32)],
) -> Vec<f64> {
    boxes
        .iter()
        .map(|&c| {
            let (p, q) = (box_lab(a, frame, c), box_lab(b, frame, c));
            (0..3).map(|i| (p[i] - q[i]).powi(2)).sum::<f64>().sqrt()
        })
        .collect()
}

fn run(args: &[&str]) {
    let r = pgrf(args);
    assert!(
        r.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&r.stderr)
    );
}

/// A reduced light frame (DNG) of a simulated 640 x 480 sensor, as
/// tests/reduce.rs makes them.
fn reduced_light(d: &Path) -> PathBuf {
    let (vs, lights) = common::sensor(d, (640, 480), false, false);
    let out = d.join("reduced");
    let r = common::reduce(&vs, &lights[..1], &out);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    out.join(lights[0].file_name().unwrap())
}

#[test]
fn darktable_and_rawtherapee_render_pgrfs_dngs_as_their_inputs() {
    if !(installed("darktable-cli") && installed("rawtherapee-cli")) {
        eprintln!("skipped: darktable-cli and rawtherapee-cli are needed (Debian: darktable, rawtherapee)");
        return;
    }
    let d = common::scratch("photo-apps", "render");
    // pgrf's noise-free chart (1200 x 800: grey patches in row 3 of the
    // 6 x 4 grid over the top 70 %), its convert and its enhance at ratio 1.
    let chart = d.join("chart.dng");
    run(&["chart", "-o", s(&chart)]);
    let (conv, enh) = (d.join("conv.dng"), d.join("enh.dng"));
    run(&["convert", s(&chart), "-o", s(&conv)]);
    run(&[
        "enhance",
        s(&chart),
        "--ratio",
        "1",
        "-o",
        s(&enh),
        "--quiet",
    ]);
    let greys: Vec<(u32, u32)> = (0..6).map(|c| (100 + 200 * c, 490)).collect();
    // The built-in 550D photo and its convert (patch centres as
    // bench/chart_look.py has them: row 3 at y 925).
    let photo = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/canon550d_colorchart.dng");
    let photo_conv = d.join("photo_conv.dng");
    run(&["convert", s(&photo), "-o", s(&photo_conv)]);
    let photo_greys: Vec<(u32, u32)> = (0..6).map(|c| (712 + 108 * c, 925)).collect();
    let light = reduced_light(&d);
    for app in [App::Darktable, App::RawTherapee] {
        let input = render(app, &chart, &d);
        for (name, out) in [("convert", &conv), ("enhance", &enh)] {
            let de = delta_e(&input, &render(app, out, &d), (1200, 800), &greys);
            assert!(
                de.iter().all(|&e| e <= 1.0),
                "{app:?} {name}: ΔE*ab {de:.3?}"
            );
        }
        let de = delta_e(
            &render(app, &photo, &d),
            &render(app, &photo_conv, &d),
            (1734, 1156),
            &photo_greys,
        );
        assert!(
            de.iter().all(|&e| e <= 1.0),
            "{app:?} 550D convert: ΔE*ab {de:.3?}"
        );
        let img = render(app, &light, &d);
        let (w, h) = (img.width(), img.height());
        assert!(
            (632..=640).contains(&w) && (472..=480).contains(&h),
            "{app:?} reduce: {w} x {h}"
        );
    }
}
