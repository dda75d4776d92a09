//! Procedural scenes: determinism, statistics, edges, and agreement between
//! the RGB, packed and frame renderers.

use pgrf_raw::ndarray::{Array3, Axis};
use pgrf_raw::{pack_normalized, Cfa};
use pgrf_scenes::scene::{render_packed_cfa, render_rgb, Scene};
use pgrf_scenes::{render_frame, render_packed, SceneKind, SceneLevels, SceneSpec};
use sha2::{Digest, Sha256};
use std::time::Instant;

fn dl(w: usize, h: usize, seed: u64) -> SceneSpec {
    SceneSpec::new(SceneKind::DeadLeaves, w, h, seed)
}

fn digest_f32(a: &Array3<f32>) -> Vec<u8> {
    let mut h = Sha256::new();
    for v in a.iter() {
        h.update(v.to_le_bytes());
    }
    h.finalize().to_vec()
}

/// Mosaic an RGB render through `cfa` and pack it, by hand.
fn mosaic_and_pack(rgb: &Array3<f32>, cfa: Cfa) -> Array3<f32> {
    let (h, w) = (rgb.shape()[0], rgb.shape()[1]);
    let off = cfa.offsets();
    Array3::from_shape_fn((4, h / 2, w / 2), |(p, i, j)| {
        let (r, c) = (2 * i + off[p].0, 2 * j + off[p].1);
        rgb[[r, c, cfa.color_at(r, c)]]
    })
}

#[test]
fn same_seed_same_bytes_different_seed_different_image() {
    let a = render_packed(&dl(256, 192, 11));
    let b = render_packed(&dl(256, 192, 11));
    assert_eq!(digest_f32(&a), digest_f32(&b));
    let c = render_packed(&dl(256, 192, 12));
    assert_ne!(digest_f32(&a), digest_f32(&c));
    // Different, not just a few pixels apart.
    let differing = a.iter().zip(c.iter()).filter(|(x, y)| x != y).count();
    assert!(differing > a.len() / 2, "{differing} of {}", a.len());

    let levels = SceneLevels::default();
    let f1 = render_frame(&dl(130, 98, 3), Cfa::Gbrg, &levels).unwrap();
    let f2 = render_frame(&dl(130, 98, 3), Cfa::Gbrg, &levels).unwrap();
    assert_eq!(f1.mosaic, f2.mosaic);
    let f3 = render_frame(&dl(130, 98, 4), Cfa::Gbrg, &levels).unwrap();
    assert_ne!(f1.mosaic, f3.mosaic);
}

#[test]
fn render_does_not_depend_on_the_thread_pool() {
    let spec = dl(200, 160, 77);
    let here = digest_f32(&render_packed(&spec));
    for threads in [1, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let there = pool.install(|| digest_f32(&render_packed(&spec)));
        assert_eq!(here, there, "{threads} threads");
    }
}

#[test]
fn dead_leaves_statistics_are_natural() {
    let (mut n, mut sum, mut saturated, mut dark) = (0usize, 0f64, 0usize, 0usize);
    let mut per_seed_mean = Vec::new();
    for seed in 0..8 {
        let p = render_packed(&dl(256, 256, 1000 + seed));
        assert_eq!(p.shape(), [4, 128, 128]);
        assert!(p.iter().all(|v| (0.0..=1.0).contains(v)), "seed {seed}");
        let s: f64 = p.iter().map(|&v| v as f64).sum();
        per_seed_mean.push(s / p.len() as f64);
        sum += s;
        n += p.len();
        saturated += p.iter().filter(|&&v| v >= 1.0).count();
        dark += p.iter().filter(|&&v| v < 0.01).count();
    }
    let mean = sum / n as f64;
    let sat = saturated as f64 / n as f64;
    let dark = dark as f64 / n as f64;
    eprintln!("mean {mean:.4} per seed {per_seed_mean:.3?} saturated {sat:.5} dark {dark:.4}");
    assert!((0.05..0.5).contains(&mean), "mean level {mean}");
    assert!((0.0005..0.05).contains(&sat), "saturated share {sat}");
    assert!(
        (0.005..0.12).contains(&dark),
        "share below 1% of full scale {dark}"
    );
    // Scenes differ in brightness but none is black or blown out.
    for m in per_seed_mean {
        assert!((0.02..0.7).contains(&m), "{m}");
    }
}

#[test]
fn every_pixel_is_covered_by_a_disc() {
    for seed in 0..4 {
        let (w, h) = (513, 385);
        let s = Scene::new(&dl(w, h, seed));
        let n = s.regions() as u32;
        for r in 0..h {
            for c in 0..w {
                assert!(s.region_at(r, c) < n, "seed {seed} ({r}, {c})");
            }
        }
        let rgb = s.rgb();
        assert!(rgb.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)));
    }
}

#[test]
fn edges_are_sharp_and_regions_many() {
    let spec = dl(256, 256, 5);
    let s = Scene::new(&spec);
    let rgb = s.rgb();
    let g = rgb.index_axis(Axis(2), 1);
    // Horizontal neighbours in different regions: a sharp edge is one pixel
    // wide, so some of those pairs jump by a large fraction of full scale.
    let (mut boundary, mut big_jumps) = (0usize, 0usize);
    for r in 0..256 {
        for c in 0..255 {
            if s.region_at(r, c) != s.region_at(r, c + 1) {
                boundary += 1;
                if (g[[r, c]] - g[[r, c + 1]]).abs() > 0.2 {
                    big_jumps += 1;
                }
            }
        }
    }
    let mut ids: Vec<u32> = (0..256 * 256)
        .map(|i| s.region_at(i / 256, i % 256))
        .collect();
    ids.sort_unstable();
    ids.dedup();
    eprintln!(
        "regions {} visible {} boundary pairs {boundary} big jumps {big_jumps} discs drawn {}",
        s.regions(),
        ids.len(),
        s.discs_drawn()
    );
    assert!(ids.len() > 1000, "only {} visible regions", ids.len());
    assert!(
        big_jumps > 100,
        "{big_jumps} jumps > 0.2 at {boundary} boundaries"
    );
    // Inside regions the image is smooth: neighbours within one region
    // rarely differ by as much as across boundaries.
    let mut inside_big = 0usize;
    let mut inside = 0usize;
    for r in 0..256 {
        for c in 0..255 {
            if s.region_at(r, c) == s.region_at(r, c + 1) {
                inside += 1;
                if (g[[r, c]] - g[[r, c + 1]]).abs() > 0.2 {
                    inside_big += 1;
                }
            }
        }
    }
    assert!(
        (inside_big as f64 / inside as f64) < 0.1 * big_jumps as f64 / boundary as f64,
        "{inside_big} of {inside} inside vs {big_jumps} of {boundary} across"
    );
}

#[test]
fn packed_matches_mosaiced_rgb_for_every_phase() {
    for (k, cfa) in Cfa::ALL.into_iter().enumerate() {
        for kind in SceneKind::ALL {
            // Odd sizes: the trailing row/column belongs to no 2x2 cell.
            let spec = SceneSpec::new(kind, 97, 64, 300 + k as u64);
            let rgb = render_rgb(&spec);
            assert_eq!(rgb.shape(), [64, 97, 3]);
            let packed = render_packed_cfa(&spec, cfa);
            // Bit for bit against mosaicing by hand.
            assert_eq!(packed, mosaic_and_pack(&rgb, cfa), "{kind} {cfa}");
            // Within one DN (rounding) against the frame through the normaliser.
            let levels = SceneLevels {
                black: [512.0, 510.0, 514.0, 508.0],
                ..Default::default()
            };
            let frame = render_frame(&spec, cfa, &levels).unwrap();
            let norm = pack_normalized(&frame, false).unwrap();
            let worst = norm
                .iter()
                .zip(packed.iter())
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            assert!(worst <= 1.0 / (16383.0 - 514.0), "{kind} {cfa}: {worst}");
            // The laid-out scene (id map) and the painting renderers agree.
            let scene = Scene::new(&spec);
            assert_eq!(scene.packed(cfa), packed, "{kind} {cfa}");
            assert_eq!(scene.frame(cfa, &levels).unwrap().mosaic, frame.mosaic);
        }
    }
    assert_eq!(
        render_packed(&dl(64, 64, 1)),
        render_packed_cfa(&dl(64, 64, 1), Cfa::Rggb)
    );
}

#[test]
fn frame_has_the_requested_layout_and_levels() {
    let levels = SceneLevels {
        black: [600.0, 601.0, 602.0, 603.0],
        white: 15000,
        bits: 14,
    };
    for kind in SceneKind::ALL {
        let f = render_frame(&SceneSpec::new(kind, 120, 80, 9), Cfa::Bggr, &levels).unwrap();
        assert_eq!((f.width, f.height), (120, 80));
        assert_eq!(f.mosaic.len(), 120 * 80);
        assert_eq!(f.cfa, Cfa::Bggr);
        assert_eq!(f.black, levels.black);
        assert_eq!((f.white, f.bits), (15000, 14));
        assert_eq!(f.make, "pgrf");
        assert!(f.model.contains(kind.name()), "{}", f.model);
        assert!(f.wb.is_some() && f.color_matrix().is_some());
        for r in 0..80 {
            for c in 0..120 {
                let v = f.at(r, c) as f32;
                assert!(v >= f.black_at(r, c) && v <= 15000.0, "({r},{c}) {v}");
            }
        }
    }
    // The gradient spans the whole range: black at one edge, white at another.
    let g = render_frame(
        &SceneSpec::new(SceneKind::Gradient, 120, 80, 0),
        Cfa::Rggb,
        &SceneLevels::default(),
    )
    .unwrap();
    assert_eq!(g.at(0, 0), 512, "R at the left edge");
    assert_eq!(g.at(79, 118), 16383, "G on the bottom row");
    assert_eq!(g.at(79, 119), 512, "B in the bottom-right corner");
    let b = 512.0 + (1.0 - 2.0 / 198.0) * (16383.0 - 512.0);
    assert_eq!(g.at(1, 1), (b as f32).round() as u16, "B near the top-left");
}

/// CPU time this thread has run, in ms (Linux's schedstat), so timings on a
/// busy machine do not count the time spent waiting for a core.
fn thread_cpu_ms() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    Some(s.split_whitespace().next()?.parse::<f64>().ok()? / 1e6)
}

/// Timing for the data loader: `cargo test --release -p pgrf-raw --test
/// scene -- --ignored --nocapture`. Reports the fastest and the median of
/// 20 seeds, wall clock and on-CPU time of this thread (the renderer is
/// serial).
#[test]
#[ignore]
fn time_render_packed_1024() {
    let stats = |f: &mut dyn FnMut()| {
        let (mut wall, mut cpu): (Vec<f64>, Vec<f64>) = (0..20)
            .map(|_| {
                let (t, c) = (Instant::now(), thread_cpu_ms());
                f();
                let c = thread_cpu_ms().zip(c).map_or(f64::NAN, |(b, a)| b - a);
                (t.elapsed().as_secs_f64() * 1e3, c)
            })
            .unzip();
        wall.sort_by(f64::total_cmp);
        cpu.sort_by(f64::total_cmp);
        format!(
            "wall best {:.1} ms, median {:.1} ms; on-CPU best {:.1} ms, median {:.1} ms",
            wall[0], wall[10], cpu[0], cpu[10]
        )
    };
    let mut seed = 0;
    let packed = stats(&mut || {
        seed += 1;
        std::hint::black_box(render_packed(&dl(1024, 1024, seed)));
    });
    eprintln!("render_packed 1024x1024 mosaic (512x512 packed): {packed}");
    let mut seed = 0;
    let laid_out = stats(&mut || {
        seed += 1;
        std::hint::black_box(Scene::new(&dl(1024, 1024, seed)));
    });
    eprintln!("  Scene::new (id map): {laid_out}");
    let s = Scene::new(&dl(1024, 1024, 1));
    eprintln!(
        "  seed 1: {} discs drawn, {} visible",
        s.discs_drawn(),
        s.regions()
    );
}
