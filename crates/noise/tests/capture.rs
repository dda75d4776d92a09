//! A simulated dark capture: un-amplified, in the clean frame's layout, with
//! its own ISO and exposure, and on average the clean frame / ratio.

use pgrf_noise::capture::DarkCapture;
use pgrf_noise::{CameraProfile, ModelKind};
use pgrf_raw::{pack_normalized, Cfa};
use pgrf_scenes::{render_frame, SceneKind, SceneLevels, SceneSpec};

fn capture(ratio: f32, seed: u64) -> DarkCapture {
    DarkCapture {
        profile: CameraProfile::built_in("sony-a7s2").unwrap(),
        model: ModelKind::Pgrf,
        iso: 1600,
        exposure_s: 0.01,
        ratio,
        seed,
    }
}

#[test]
fn dark_frame_is_the_clean_frame_divided_by_the_ratio_plus_noise() {
    // A smooth scene, so the mean over many pixels tests the level alone.
    let spec = SceneSpec::new(SceneKind::Gradient, 256, 192, 0);
    let clean = render_frame(&spec, Cfa::Grbg, &SceneLevels::default()).unwrap();
    let dark = capture(100.0, 7).take(&clean).unwrap();
    assert_eq!(
        (dark.width, dark.height, dark.cfa, dark.black, dark.white),
        (
            clean.width,
            clean.height,
            clean.cfa,
            clean.black,
            clean.white
        )
    );
    assert_eq!((dark.iso, dark.exposure_s), (Some(1600), Some(0.01)));
    let c = pack_normalized(&clean, false).unwrap();
    let d = pack_normalized(&dark, false).unwrap();
    // Mean of dark x 100 against the clean mean: the pgrf model's noise is
    // zero-mean apart from its small dark-current offset, so 3% of the level
    // bounds it; noise std per pixel at this level is ~ 0.4 of the level /
    // 100, i.e. ~1e-3 over 49k pixels per plane.
    for p in 0..4 {
        let cm = c.index_axis(pgrf_raw::ndarray::Axis(0), p).mean().unwrap() as f64;
        let dm = d.index_axis(pgrf_raw::ndarray::Axis(0), p).mean().unwrap() as f64 * 100.0;
        assert!(
            (dm - cm).abs() < 0.03 * cm + 0.01,
            "plane {p}: dark x100 mean {dm:.4} vs clean {cm:.4}"
        );
    }
    // Noise is there: neighbouring pixels of a smooth ramp differ far more
    // than the ramp's own step.
    let rough: f64 = d
        .windows((1, 1, 2))
        .into_iter()
        .map(|w| ((w[[0, 0, 1]] - w[[0, 0, 0]]) as f64 * 100.0).abs())
        .sum::<f64>()
        / (4 * 96 * 127) as f64;
    assert!(rough > 0.02, "mean neighbour difference x100 {rough}");
    // Same seed, same frame; other seed, other noise.
    assert_eq!(capture(100.0, 7).take(&clean).unwrap().mosaic, dark.mosaic);
    assert_ne!(capture(100.0, 8).take(&clean).unwrap().mosaic, dark.mosaic);
}

#[test]
fn bad_ratios_are_refused() {
    let spec = SceneSpec::new(SceneKind::Gradient, 64, 64, 0);
    let clean = render_frame(&spec, Cfa::Rggb, &SceneLevels::default()).unwrap();
    for r in [0.0, -2.0, f32::NAN, f32::INFINITY] {
        let e = capture(r, 0).take(&clean).unwrap_err();
        assert!(
            e.to_string().contains("ratio must be a positive number"),
            "{e}"
        );
    }
}

#[test]
fn the_dark_level_is_what_the_capture_carries_above_the_scene() {
    // The A7S2's black-level error at ISO 1600 is +2.428 DN on its
    // 16,383 - 512 DN range; on this frame's range it is the same fraction.
    // Averaged over 8 seeds of a smooth ramp (~400k samples per plane), the
    // capture x100 sits that far above the clean frame: 0.0153 of full
    // scale, measured to ~5e-4 (noise), with the pgrf model's small dark
    // current on top (0.01 s), inside the 0.002 tolerance.
    let spec = SceneSpec::new(SceneKind::Gradient, 256, 192, 0);
    let clean = render_frame(&spec, Cfa::Rggb, &SceneLevels::default()).unwrap();
    let level = capture(100.0, 0).dark_level_dn(&clean).unwrap();
    assert_eq!(level.shape(), &[4, 96, 128]);
    let c = pack_normalized(&clean, false).unwrap();
    for p in 0..4 {
        let plane = level.index_axis(pgrf_raw::ndarray::Axis(0), p);
        let range = clean.white as f64 - clean.black[p] as f64;
        let want = 100.0 * plane[[0, 0]] as f64 / range;
        assert!((want - 100.0 * 2.428175 / 15871.0).abs() < 1e-5, "{want}");
        assert!(plane.iter().all(|&v| v == plane[[0, 0]]));
        let cm = c.index_axis(pgrf_raw::ndarray::Axis(0), p).mean().unwrap() as f64;
        let lifted: f64 = (0..8)
            .map(|seed| {
                let d =
                    pack_normalized(&capture(100.0, seed).take(&clean).unwrap(), false).unwrap();
                d.index_axis(pgrf_raw::ndarray::Axis(0), p).mean().unwrap() as f64 * 100.0 - cm
            })
            .sum::<f64>()
            / 8.0;
        assert!(
            (lifted - want).abs() < 0.002,
            "plane {p}: capture x100 is {lifted:.5} above the scene, the dark level {want:.5}"
        );
    }
}
