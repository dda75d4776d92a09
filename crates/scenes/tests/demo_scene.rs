//! The demo's scene: reproducible from its seed, the chart's patches carry
//! the ColorChecker's camera values, the ramp is linear, and the frame's
//! statistics are those of a well-exposed photo.

use pgrf_raw::{pack_normalized, Cfa};
use pgrf_scenes::chart::{patch_camera_rgb, A7S2_D65_MATRIX};
use pgrf_scenes::demo::{render_demo, DemoLayout, DEMO_CHART_EXPOSURE, DEMO_RAMP_TOP};
use pgrf_scenes::SceneLevels;

const W: usize = 384;
const H: usize = 256;

#[test]
fn same_seed_same_bytes_other_seed_other_leaves() {
    let levels = SceneLevels::default();
    let a = render_demo(W, H, 3, Cfa::Rggb, &levels).unwrap();
    let b = render_demo(W, H, 3, Cfa::Rggb, &levels).unwrap();
    let c = render_demo(W, H, 4, Cfa::Rggb, &levels).unwrap();
    assert_eq!(a.mosaic, b.mosaic);
    let differ = a
        .mosaic
        .iter()
        .zip(&c.mosaic)
        .filter(|(x, y)| x != y)
        .count();
    // The leaves change; the chart and ramp (about a quarter) do not.
    assert!(
        differ > a.mosaic.len() / 3,
        "{differ} of {}",
        a.mosaic.len()
    );
    assert!(
        differ < a.mosaic.len() * 9 / 10,
        "{differ} of {}",
        a.mosaic.len()
    );
    assert_eq!((a.width, a.height, a.cfa), (W, H, Cfa::Rggb));
    assert_eq!(a.color_matrices[0].xyz_to_cam, A7S2_D65_MATRIX);
}

#[test]
fn chart_patches_and_ramp_have_their_camera_values() {
    let levels = SceneLevels::default();
    for cfa in Cfa::ALL {
        let f = render_demo(W, H, 0, cfa, &levels).unwrap();
        let range = (levels.white as f32 - levels.black[0]) as f64;
        let layout = DemoLayout::new(W, H);
        for i in 0..24 {
            let (r0, r1, c0, c1) = layout.patch_box(i);
            assert!(r1 > r0 + 2 && c1 > c0 + 2, "patch {i} too small");
            let want = patch_camera_rgb(i).map(|v| (DEMO_CHART_EXPOSURE * v) as f64);
            for r in r0..r1 {
                for c in c0..c1 {
                    let ch = cfa.color_at(r, c);
                    let got = (f.mosaic[r * W + c] as f64 - levels.black[0] as f64) / range;
                    // Rounding to DN: half a DN.
                    assert!(
                        (got - want[ch]).abs() <= 0.5 / range + 1e-9,
                        "{cfa} patch {i} ({r}, {c}) channel {ch}: {got} vs {}",
                        want[ch]
                    );
                }
            }
        }
        // The ramp's green rises linearly from 0 to DEMO_RAMP_TOP x green's
        // share of a neutral (green is the strongest A7S2 channel: 1).
        let (rr, (c0, c1)) = (layout.ramp_rows.0 + 2, layout.ramp_cols);
        let green_col = |c: usize| if cfa.color_at(rr, c) == 1 { c } else { c + 1 };
        let at = |c: usize| (f.mosaic[rr * W + green_col(c)] as f64 - 512.0) / range;
        // At most one ramp step (the first green sample may be one column in).
        let step = DEMO_RAMP_TOP as f64 / (c1 - c0 - 1) as f64;
        assert!(at(c0) <= step + 1.0 / range, "{}", at(c0));
        let top = at(c1 - 2);
        assert!((top - DEMO_RAMP_TOP as f64).abs() < 0.01, "{top}");
        let mid = at((c0 + c1) / 2);
        assert!((mid - DEMO_RAMP_TOP as f64 / 2.0).abs() < 0.01, "{mid}");
    }
}

#[test]
fn statistics_are_those_of_a_well_exposed_photo() {
    let mut means = Vec::new();
    for seed in 0..4 {
        let f = render_demo(W, H, seed, Cfa::Rggb, &SceneLevels::default()).unwrap();
        let p = pack_normalized(&f, true).unwrap();
        let n = p.len() as f64;
        let mean = p.iter().map(|&v| v as f64).sum::<f64>() / n;
        let saturated = p.iter().filter(|&&v| v >= 1.0).count() as f64 / n;
        eprintln!("seed {seed}: mean {mean:.4}, saturated {saturated:.5}");
        // The chart and ramp never clip; the leaves clip a few highlights.
        assert!(
            (0.08..0.45).contains(&mean),
            "seed {seed}: mean level {mean}"
        );
        assert!(saturated < 0.03, "seed {seed}: saturated share {saturated}");
        means.push(mean);
    }
    assert!(means.windows(2).any(|w| (w[0] - w[1]).abs() > 1e-3));
}

#[test]
fn bad_sizes_are_refused() {
    for (w, h) in [(63, 64), (64, 62), (32, 64), (65, 66)] {
        let e = render_demo(w, h, 0, Cfa::Rggb, &SceneLevels::default()).unwrap_err();
        assert!(e.to_string().contains("even and at least 64"), "{e}");
    }
}
