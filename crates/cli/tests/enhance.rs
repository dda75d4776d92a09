//! `pgrf enhance` as scripts use it: the written DNG keeps the input's
//! geometry, levels and metadata and holds exactly the model's output; the
//! flow model's searched t2 is used; batches skip unreadable files; bad input
//! gives one line and writes nothing.

mod common;
use common::{one_line_error, pgrf, s};

use pgrf_nn::backend::{Cpu, DeviceKind};
use pgrf_nn::infer::prepare::network_input;
use pgrf_nn::infer::{restore_image, ImageOptions, SamplerChoice};
use pgrf_raw::{
    decode_file, pack_normalized, unpack_normalized, write_dng, Cfa, DngOptions, LevelOverrides,
    RawFrame,
};
use pgrf_scenes::scene::{render_frame, SceneKind, SceneLevels, SceneSpec};
use serde_json::Value;
use std::path::{Path, PathBuf};

fn scratch(name: &str) -> PathBuf {
    common::scratch("enhance", name)
}

fn files_in(d: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Small networks with fixed (seeded) weights: what matters here is the
/// plumbing, not the denoising.
fn model(dir: &Path, flow: bool, t2: Option<f32>) -> PathBuf {
    common::tiny_model(dir, flow, t2, 11)
}

/// A dark dead-leaves frame (values scaled down ~100x above black) with
/// camera metadata, as a DNG.
fn dark_dng(path: &Path, w: usize, h: usize, cfa: Cfa, seed: u64) -> RawFrame {
    let levels = SceneLevels::default();
    let mut f = render_frame(
        &SceneSpec::new(SceneKind::DeadLeaves, w, h, seed),
        cfa,
        &levels,
    )
    .unwrap();
    for v in f.mosaic.iter_mut() {
        let above = *v as f32 - 512.0;
        *v = (512.0 + above / 100.0 + ((seed as usize + *v as usize) % 7) as f32).round() as u16;
    }
    f.iso = Some(1600);
    f.exposure_s = Some(1.0 / 100.0);
    f.make = "Sony".into();
    f.model = "ILCE-7SM2".into();
    f.wb = Some([2.1, 1.0, 1.6]);
    write_dng(&f, path, &DngOptions::default()).unwrap();
    decode_file(path, &LevelOverrides::default()).unwrap()
}

#[test]
fn the_dng_keeps_the_input_and_holds_the_model_output() {
    let d = scratch("dng");
    let noisy = d.join("noisy.dng");
    // GBRG, 304x224 packed: 3 x 2 tiles of 144 packed pixels (the smallest
    // a user may ask for) with overlap 64.
    let input = dark_dng(&noisy, 608, 448, Cfa::Gbrg, 3);
    for flow in [false, true] {
        let m = model(&d, flow, Some(0.3));
        let out = d.join(format!("out-{flow}.dng"));
        let png = d.join(format!("out-{flow}.png"));
        let r = pgrf(&[
            "enhance",
            s(&noisy),
            "--model",
            s(&m),
            "--ratio",
            "80",
            "-o",
            s(&out),
            "--png",
            s(&png),
            "--tile",
            "144",
            "--overlap",
            "64",
            "--json",
            "--quiet",
        ]);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        let report: Value = serde_json::from_slice(&r.stdout).unwrap();
        // 224 x 304 packed, mirrored by 4 on every side: 232 x 312 in tiles
        // of 144 (128 as run) overlapping by 64, 3 x 4 of them.
        assert_eq!(report["tiles"], 12, "{report}");
        assert_eq!(report["nfe"], if flow { 2 } else { 1 });
        // The stages' seconds are each the file's and add up to at most its
        // total; the network and the preview took some.
        let stage = |k: &str| report["stages"][k].as_f64().unwrap();
        let parts = ["decode", "prepare", "network", "write", "preview"].map(stage);
        let total = report["seconds"].as_f64().unwrap();
        assert!(parts.iter().all(|&p| p >= 0.0), "{report}");
        assert!(parts.iter().sum::<f64>() <= total + 1e-6, "{report}");
        assert!(parts[2] > 0.0 && parts[4] > 0.0, "{report}");

        let got = decode_file(&out, &LevelOverrides::default()).unwrap();
        assert_eq!((got.width, got.height), (input.width, input.height));
        assert_eq!(got.cfa, input.cfa);
        assert_eq!(got.black, input.black);
        assert_eq!(got.white, input.white);
        assert_eq!((got.iso, got.exposure_s), (input.iso, input.exposure_s));
        assert_eq!((&got.make, &got.model), (&input.make, &input.model));
        assert_eq!(got.wb, input.wb);
        assert_eq!(got.color_matrices, input.color_matrices);
        assert_eq!(got.orientation, input.orientation);

        // The pixels are the model's output, unpacked to the input's levels.
        let restorer = pgrf_nn::infer::load(&m, SamplerChoice::default(), DeviceKind::Cpu).unwrap();
        let x = network_input(&input, 80.0, None).unwrap();
        let y = restore_image(
            restorer.as_ref(),
            x.view(),
            &ImageOptions {
                tile: 144,
                overlap: 64,
                seed: 0,
                noise: None,
            },
            &pgrf_core::NoProgress,
        )
        .unwrap();
        let expect = unpack_normalized(y.view(), &input).unwrap();
        let differ = got
            .mosaic
            .iter()
            .zip(&expect.mosaic)
            .filter(|(a, b)| a != b)
            .count();
        assert_eq!(differ, 0, "flow {flow}: {differ} pixels differ");
        // The output is not the input: the network did something.
        assert_ne!(pack_normalized(&got, true).unwrap(), x);
        let img = image::open(&png).unwrap();
        assert_eq!((img.width(), img.height()), (608, 448));
    }
}

#[test]
fn the_flow_model_uses_the_searched_t2_from_its_file() {
    let d = scratch("t2");
    let noisy = d.join("noisy.dng");
    dark_dng(&noisy, 64, 64, Cfa::Rggb, 5);
    let m = model(&d, true, Some(0.3));
    let run = |out: &Path, extra: &[&str]| {
        let mut args = vec![
            "enhance",
            s(&noisy),
            "--model",
            s(&m),
            "--ratio",
            "50",
            "-o",
            s(out),
            "--quiet",
        ];
        args.extend_from_slice(extra);
        let r = pgrf(&args);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        decode_file(out, &LevelOverrides::default()).unwrap().mosaic
    };
    let from_file = run(&d.join("a.dng"), &[]);
    let explicit = run(&d.join("b.dng"), &["--t2", "0.3"]);
    let other = run(&d.join("c.dng"), &["--t2", "0.9"]);
    assert_eq!(from_file, explicit);
    assert_ne!(from_file, other);
    // Averaging two samples differs from one sample.
    let two = run(&d.join("e.dng"), &["--samples", "2"]);
    assert_ne!(from_file, two);
}

#[test]
fn a_batch_skips_and_lists_unreadable_files() {
    let d = scratch("batch");
    let inputs = d.join("in");
    std::fs::create_dir(&inputs).unwrap();
    dark_dng(&inputs.join("a.dng"), 48, 32, Cfa::Rggb, 1);
    dark_dng(&inputs.join("c.dng"), 48, 32, Cfa::Bggr, 2);
    std::fs::write(inputs.join("b.ARW"), b"not a raw file").unwrap();
    let m = model(&d, false, None);
    let out = d.join("out");
    let r = pgrf(&[
        "enhance",
        s(&inputs),
        "--model",
        s(&m),
        "--ratio",
        "100",
        "-o",
        s(&out),
        "--png",
        "--quiet",
    ]);
    let err = String::from_utf8_lossy(&r.stderr);
    // Exit 3: the batch ran to its end, some files failed.
    assert_eq!(r.status.code(), Some(3), "{err}");
    assert!(
        err.contains("1 of 3 files failed") && err.contains("b.ARW"),
        "{err}"
    );
    assert_eq!(files_in(&out), ["a.dng", "a.png", "c.dng", "c.png"]);
}

/// Fuji's 6x6 X-Trans mosaic, written with rawler's DNG writer.
fn xtrans_dng(path: &Path) {
    use rawler::cfa::{PlaneColor, CFA};
    use rawler::decoders::Camera;
    use rawler::dng::writer::DngWriter;
    use rawler::dng::{CropMode, DngCompression, DngPhotometricConversion, DNG_VERSION_V1_4};
    use rawler::pixarray::PixU16;
    use rawler::rawimage::{CFAConfig, RawImage, RawPhotometricInterpretation, WhiteLevel};
    let mut cam = Camera::new();
    cam.make = "Fujifilm".into();
    cam.model = "X-T3".into();
    cam.cfa = CFA::new("GGRGGBGGBGGRBRGRBGGGBGGRGGRGGBRBRBRG");
    cam.plane_color = PlaneColor::new("RGB");
    cam.real_bps = 14;
    let photometric = RawPhotometricInterpretation::Cfa(CFAConfig::new(&cam.cfa, &cam.plane_color));
    let pixels = PixU16::new_with(vec![1000u16; 48 * 36], 48, 36);
    let image = RawImage::new(
        cam,
        pixels,
        1,
        [1.0, 1.0, 1.0, f32::NAN],
        photometric,
        None,
        Some(WhiteLevel::new(vec![16383])),
        false,
    );
    let mut buf = std::io::Cursor::new(Vec::new());
    let mut dng = DngWriter::new(&mut buf, DNG_VERSION_V1_4).unwrap();
    let mut raw = dng.subframe_on_root(0);
    raw.raw_image(
        &image,
        CropMode::None,
        DngCompression::Uncompressed,
        DngPhotometricConversion::Original,
        1,
    )
    .unwrap();
    raw.finalize().unwrap();
    dng.load_base_tags(&image).unwrap();
    dng.close().unwrap();
    std::fs::write(path, buf.into_inner()).unwrap();
}

#[test]
fn bad_input_gives_one_line_and_writes_nothing() {
    let d = scratch("bad");
    let noisy = d.join("noisy.dng");
    dark_dng(&noisy, 48, 32, Cfa::Rggb, 1);
    // 200 x 32 packed: wider than the smallest tile a user may ask for.
    let wide = d.join("wide.dng");
    dark_dng(&wide, 400, 64, Cfa::Rggb, 2);
    let m = model(&d, false, None);
    let xtrans = d.join("xtrans.dng");
    xtrans_dng(&xtrans);
    let truncated = d.join("truncated.safetensors");
    std::fs::write(&truncated, &std::fs::read(&m).unwrap()[..1000]).unwrap();
    let before = files_in(&d);
    let out = d.join("out.dng");
    let cases: Vec<(Vec<&str>, &[&str])> = vec![
        // A DNG given as the model: not a weight file.
        (
            vec![
                s(&noisy),
                "--model",
                s(&noisy),
                "--ratio",
                "100",
                "-o",
                s(&out),
            ],
            &["noisy.dng"],
        ),
        (
            vec![
                s(&noisy),
                "--model",
                s(&truncated),
                "--ratio",
                "100",
                "-o",
                s(&out),
            ],
            &["truncated.safetensors"],
        ),
        (
            vec![
                s(&xtrans),
                "--model",
                s(&m),
                "--ratio",
                "100",
                "-o",
                s(&out),
            ],
            &["X-Trans"],
        ),
        (
            vec![s(&noisy), "--model", s(&m), "--ratio", "0", "-o", s(&out)],
            &["--ratio"],
        ),
        (
            vec![s(&noisy), "--model", s(&m), "--ratio", "-3", "-o", s(&out)],
            &["--ratio"],
        ),
        (
            vec![
                s(&noisy),
                "--model",
                s(&m),
                "--ratio",
                "100",
                "-o",
                "/nonexistent-dir/x.dng",
            ],
            &["/nonexistent-dir", "does not exist"],
        ),
        (
            vec![
                s(&noisy),
                "--model",
                s(&m),
                "--ratio",
                "100",
                "-o",
                s(&noisy),
            ],
            &["is the input"],
        ),
        (
            vec![
                s(&noisy),
                "--model",
                s(&m),
                "--ratio",
                "100",
                "--sampler",
                "euler:0",
                "-o",
                s(&out),
            ],
            &["euler"],
        ),
        (
            vec![
                s(&noisy),
                "--model",
                s(&m),
                "--ratio",
                "100",
                "--device",
                "cuda",
                "-o",
                s(&out),
            ],
            &["CUDA"],
        ),
        // Tiles and overlaps that would make the result depend on the
        // tiling (issue 17), refused with the bound.
        (
            vec![
                s(&wide),
                "--model",
                s(&m),
                "--ratio",
                "100",
                "--tile",
                "128",
                "-o",
                s(&out),
            ],
            &["--tile 128 is below 144", "give --tile 144 or more"],
        ),
        (
            vec![
                s(&wide),
                "--model",
                s(&m),
                "--ratio",
                "100",
                "--tile",
                "144",
                "--overlap",
                "16",
                "-o",
                s(&out),
            ],
            &["--overlap 16 is below 64"],
        ),
    ];
    for (args, expect) in cases {
        let mut full = vec!["enhance"];
        full.extend(args.iter().copied());
        let r = pgrf(&full);
        if expect == ["CUDA"] && cfg!(feature = "cuda") {
            continue;
        }
        if expect == ["euler"] {
            // clap reports argument errors with usage: exit 2, but still no panic.
            let err = String::from_utf8_lossy(&r.stderr);
            assert!(!r.status.success(), "{args:?}");
            assert!(!err.contains("panicked"), "{err}");
            assert!(expect.iter().all(|e| err.contains(e)), "{args:?}: {err}");
        } else {
            let err = one_line_error(&r);
            assert!(expect.iter().all(|e| err.contains(e)), "{args:?}: {err}");
        }
        assert_eq!(files_in(&d), before, "{args:?} left files behind");
    }
}

/// `pgrf search` scores the same two-stage sampler `enhance` runs: its PSNR
/// at a t equals the library's sampler at t2 = t on the same pairs; the best
/// t lands in the file's record and nothing else in the file changes.
#[test]
fn search_writes_the_best_t2_and_agrees_with_the_sampler() {
    use pgrf_eval::{evaluate, Protocol};
    use pgrf_nn::data::source::Source;
    use pgrf_nn::data::validation::ValSet;
    use pgrf_nn::infer::{Restore, Restorer};
    use pgrf_noise::pair::{PairSpec, RatioSpec};
    use pgrf_noise::{CameraProfile, ModelKind};

    let d = scratch("search");
    let m = model(&d, true, None);
    let (_, tensors_before) = pgrf_nn::weights::read(&m).unwrap();
    let plot = d.join("curve.png");
    let args = [
        "search",
        "--model",
        s(&m),
        "--procedural",
        "2",
        "--patch",
        "32",
        "--step",
        "0.25",
        "--plot",
        s(&plot),
        "--samples",
        "2",
        "--json",
    ];
    let r = pgrf(&args);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let j: Value = serde_json::from_slice(&r.stdout).unwrap();
    let t: Vec<f64> = serde_json::from_value(j["t"].clone()).unwrap();
    let psnr: Vec<f64> = serde_json::from_value(j["psnr"].clone()).unwrap();
    assert_eq!(t, [0.25, 0.5, 0.75, 1.0]);
    let best = j["best_t2"].as_f64().unwrap();
    // The kept t: the smallest within the default 0.01 dB of the best.
    assert_eq!(j["tolerance_db"].as_f64(), Some(0.01));
    let max = psnr.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let k = (0..4).find(|&k| psnr[k] >= max - 0.01).unwrap();
    assert_eq!(best, t[k]);
    // Averaging: K = 1 is the two-stage result at the best t; K = 2 differs.
    let avg: Vec<(usize, f64, f64)> = serde_json::from_value(j["averaged"].clone()).unwrap();
    assert_eq!(avg.len(), 2);
    assert_eq!((avg[0].0, avg[1].0), (1, 2));
    assert!((avg[0].1 - psnr[k]).abs() < 1e-9, "{avg:?}");
    assert_ne!(avg[1].1, avg[0].1);
    let (meta, tensors_after) = pgrf_nn::weights::read(&m).unwrap();
    assert_eq!(meta.t2, Some(best as f32));
    assert_eq!(tensors_before, tensors_after);
    assert!(image::open(&plot).is_ok());

    // The same pairs through the library's two-stage sampler at t = 0.5.
    let mut spec = PairSpec::new(
        CameraProfile::built_in("sony-a7s2").unwrap(),
        ModelKind::Pgrf,
    );
    spec.iso = Some(1600);
    spec.ratio = RatioSpec::Uniform {
        lo: 100.0,
        hi: 300.0,
    };
    let val = ValSet::build(&Source::Procedural, &spec.into(), 32, 2, 0).unwrap();
    let (net, meta) = pgrf_nn::model::load::<Cpu>(&m, &Default::default()).unwrap();
    let r = Restorer::new(net, meta, SamplerChoice::default(), 0.5, Default::default()).unwrap();
    let mut mean = 0.0;
    for p in &val.pairs {
        let view = |v: &Vec<f32>| {
            pgrf_raw::ndarray::ArrayView3::from_shape((4, 32, 32), v.as_slice())
                .unwrap()
                .to_owned()
        };
        let out = r
            .restore(view(&p.noisy).view(), &[view(&p.x0).view()], None)
            .unwrap();
        mean += evaluate(out.view(), view(&p.clean).view(), &Protocol::eld(false))
            .unwrap()
            .psnr
            / 2.0;
    }
    assert!(
        (mean - psnr[1]).abs() < 1e-6,
        "library {mean} vs search {}",
        psnr[1]
    );

    // A dry run leaves the file byte for byte; a denoiser is refused.
    let bytes = std::fs::read(&m).unwrap();
    let r = pgrf(&[
        "search",
        "--model",
        s(&m),
        "--procedural",
        "1",
        "--patch",
        "32",
        "--step",
        "0.5",
        "--dry-run",
        "--json",
        "--plot",
        s(&plot),
    ]);
    assert!(r.status.success());
    assert_eq!(std::fs::read(&m).unwrap(), bytes);
    for tol in ["-0.01", "0.5", "nan"] {
        let err = one_line_error(&pgrf(&[
            "search",
            "--model",
            s(&m),
            "--procedural",
            "1",
            &format!("--tolerance={tol}"),
        ]));
        assert!(
            err.contains("--tolerance must be from 0 to 0.1"),
            "{tol}: {err}"
        );
    }
    assert_eq!(std::fs::read(&m).unwrap(), bytes);
    let spc = model(&d, false, None);
    let err = one_line_error(&pgrf(&["search", "--model", s(&spc), "--procedural", "1"]));
    assert!(err.contains("flow model"), "{err}");
}

/// A calibration's fixed pattern is subtracted in DN before amplification:
/// a frame shot 5 DN brighter everywhere, enhanced with a calibration whose
/// fixed pattern is 5 DN (and no dark current), gives exactly the result of
/// the plain frame without one. A calibration of another size is refused.
#[test]
fn the_calibrated_fixed_pattern_is_subtracted() {
    use pgrf_calib::Calibration;
    use pgrf_raw::ndarray::Array3;
    let d = scratch("calib");
    let plain = d.join("plain.dng");
    let frame = dark_dng(&plain, 64, 48, Cfa::Rggb, 9);
    let mut brighter = frame.clone();
    for v in brighter.mosaic.iter_mut() {
        *v += 5;
    }
    let bright = d.join("bright.dng");
    write_dng(&brighter, &bright, &DngOptions::default()).unwrap();
    let calib = |w: usize, h: usize, path: &Path, hot: usize| {
        let meta: pgrf_calib::CalibMeta = serde_json::from_value(serde_json::json!({
            "kind": "pgrf-calibration", "schema": 1, "pgrf_version": "test",
            "make": "Sony", "model": "ILCE-7SM2", "iso": 1600, "width": w, "height": h,
            "cfa": "RGGB", "black": [512.0, 512.0, 512.0, 512.0], "white": 16383,
            "bias_frames": 16, "bias_exposure_s": 0.000125, "dark_exposures_s": [1.0],
            "dark_frames": [4], "flat_exposures_s": [0.01], "flat_frames": [4],
            "K": 1.53, "k_method": "ptc", "row_sigma": 1.0, "read_sigma_median": 3.0,
            "dsnu": 0.0, "prnu": null, "dark_law": "sqrt", "dark_r2_sqrt": null,
            "dark_r2_linear": null, "dark_rate_mean": null, "ppcc_pixel_median": null,
            "ppcc_pooled": null, "hot_pixels": 0, "dead_pixels": 0, "units": "DN"
        }))
        .unwrap();
        let shape = (4, h / 2, w / 2);
        let maps = pgrf_calib::CalibMaps {
            fixed_pattern: Array3::from_elem(shape, 5.0f32),
            sigma_read: Array3::from_elem(shape, 3.0f32),
            dark_rate: Array3::zeros(shape),
            defects: {
                // `hot` hot pixels along the diagonal of plane R.
                let mut d = Array3::zeros(shape);
                for k in 0..hot {
                    d[[0, 2 + 3 * k, 2 + 3 * k]] = 1.0;
                }
                d
            },
            gain: None,
            response: None,
            noise_bank: Vec::new(),
            r2_sqrt: None,
            r2_linear: None,
            dark_offset: None,
        };
        Calibration { meta, maps }.save(path).unwrap();
    };
    let good = d.join("good.safetensors");
    calib(64, 48, &good, 0);
    let wrong = d.join("wrong.safetensors");
    calib(32, 48, &wrong, 0);
    let hot = d.join("hot.safetensors");
    calib(64, 48, &hot, 3);
    let m = model(&d, false, None);
    let run = |input: &Path, out: &Path, extra: &[&str]| {
        let mut args = vec![
            "enhance",
            s(input),
            "--model",
            s(&m),
            "--ratio",
            "100",
            "-o",
            s(out),
            "--quiet",
        ];
        args.extend_from_slice(extra);
        pgrf(&args)
    };
    let a = d.join("a.dng");
    let b = d.join("b.dng");
    assert!(run(&plain, &a, &[]).status.success());
    let r = run(&bright, &b, &["--calib", s(&good)]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let (ra, rb) = (
        decode_file(&a, &LevelOverrides::default()).unwrap(),
        decode_file(&b, &LevelOverrides::default()).unwrap(),
    );
    assert_eq!(ra.mosaic, rb.mosaic);
    // The report counts the defective pixels the calibration's map had
    // replaced from their neighbours.
    for (cal, n) in [(&good, 0), (&hot, 3)] {
        let r = run(&bright, &d.join("j.dng"), &["--calib", s(cal), "--json"]);
        let report: Value = serde_json::from_slice(&r.stdout).unwrap();
        assert_eq!(report["defects_corrected"], n, "{report}");
    }
    let c = d.join("c.dng");
    let err = one_line_error(&run(&bright, &c, &["--calib", s(&wrong)]));
    assert!(err.contains("32x48") && err.contains("64x48"), "{err}");
    assert!(!c.exists());
}

/// A noise-aware model (trained two steps with `--conditioning
/// sigma-map`): `enhance` tells it the noise of each file and says where
/// the numbers came from, `--noise` first, else the lookup (here the DNG
/// NoiseProfile `pgrf synth` writes: the noise it drew, on the file's
/// scale); the weight file records the conditioning; a malformed `--noise`
/// is one line.
#[test]
fn a_noise_aware_model_is_told_the_noise_and_the_source_is_named() {
    let dir = scratch("noise-aware");
    let (chart, noisy, model) = (
        dir.join("chart.dng"),
        dir.join("noisy.dng"),
        dir.join("m.safetensors"),
    );
    assert!(pgrf(&[
        "chart",
        "-o",
        s(&chart),
        "--width",
        "256",
        "--height",
        "192"
    ])
    .status
    .success());
    let r = pgrf(&[
        "synth",
        s(&chart),
        "--profile",
        "sony-a7s2",
        "--iso",
        "3200",
        "--ratio",
        "50",
        "--seed",
        "1",
        "-o",
        s(&noisy),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    common::noise_aware_model(&model);
    let meta = pgrf_nn::weights::read_meta(&model).unwrap();
    assert_eq!(
        meta.arch.conditioning(),
        pgrf_nn::condition::Conditioning::SigmaMap
    );

    let run = |extra: &[&str], out: &Path| -> Value {
        let mut args = vec![
            "enhance",
            s(&noisy),
            "-m",
            s(&model),
            "--ratio",
            "50",
            "-o",
            s(out),
            "--json",
        ];
        args.extend_from_slice(extra);
        let r = pgrf(&args);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        serde_json::from_slice(&r.stdout).unwrap()
    };
    let j = run(&[], &dir.join("a.dng"));
    let said = j["noise"].as_str().unwrap();
    assert!(said.contains("(the file's DNG NoiseProfile tag)"), "{said}");
    // The A7S2's K at ISO 3200 on the chart's scale (white - black).
    let p = pgrf_noise::CameraProfile::built_in("sony-a7s2")
        .unwrap()
        .params_at_iso(3200)
        .unwrap();
    let f = pgrf_raw::decode_file(&noisy, &Default::default()).unwrap();
    let k = p.k / (16383.0 - 512.0) * (f.white as f64 - f.black[0] as f64);
    assert!(
        said.starts_with(&format!("K {k:.4} DN/e-")),
        "{said} vs {k}"
    );
    let j = run(&["--noise", "K=3,read=4,row=0.5"], &dir.join("b.dng"));
    assert_eq!(
        j["noise"],
        "K 3.0000 DN/e-, read 4.000 DN, row 0.500 DN (--noise)"
    );

    let r = pgrf(&[
        "enhance",
        s(&noisy),
        "-m",
        s(&model),
        "--ratio",
        "50",
        "-o",
        s(&dir.join("c.dng")),
        "--noise",
        "K=3",
    ]);
    // A value clap refuses: its usage error (exit 2), first line pgrf's.
    let err = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(2), "{err}");
    assert!(
        err.starts_with("pgrf: error: ") && err.contains("give at least K=.. and read=.."),
        "{err}"
    );
    assert!(!dir.join("c.dng").exists());
}

/// Without --ratio or --target-exposure the ratio is metered from the frame
/// (issue 36, item 7): the report names it and how it was chosen, and it is
/// the one `auto_ratio` computes, which brings the frame's mean level to
/// 1/8 of white; `--ratio auto` is the same; a frame at black is refused.
#[test]
fn without_a_ratio_the_frame_is_metered_and_the_choice_printed() {
    let d = scratch("auto");
    let noisy = d.join("noisy.dng");
    let input = dark_dng(&noisy, 128, 96, Cfa::Rggb, 5);
    let m = model(&d, false, None);
    let want = pgrf_nn::infer::prepare::auto_ratio(&input, None).unwrap();
    assert!(want.ratio > 20.0 && want.ratio < 300.0, "{want:?}");
    for extra in [&[][..], &["--ratio", "auto"][..]] {
        let out = d.join("out.dng");
        let mut args = vec![
            "enhance",
            s(&noisy),
            "--model",
            s(&m),
            "-o",
            s(&out),
            "--json",
        ];
        args.extend_from_slice(extra);
        let r = pgrf(&args);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        let report: Value = serde_json::from_slice(&r.stdout).unwrap();
        assert_eq!(report["ratio"].as_f64().unwrap() as f32, want.ratio);
        let how = report["ratio_auto"].as_str().unwrap();
        assert!(
            how.starts_with("auto: mean level") && how.contains("0.125"),
            "{how}"
        );
        std::fs::remove_file(&out).unwrap();
    }
    let plain = pgrf(&[
        "enhance",
        s(&noisy),
        "--model",
        s(&m),
        "-o",
        s(&d.join("p.dng")),
    ]);
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&plain.stdout),
        String::from_utf8_lossy(&plain.stderr)
    );
    assert!(
        text.contains(&format!("ratio {:.1} (auto: mean level", want.ratio)),
        "{text}"
    );

    let word = pgrf(&[
        "enhance",
        s(&noisy),
        "--model",
        s(&m),
        "--ratio",
        "bright",
        "-o",
        s(&d.join("w.dng")),
    ]);
    let e = String::from_utf8_lossy(&word.stderr);
    assert_eq!(word.status.code(), Some(2), "{e}");
    assert!(
        e.starts_with("pgrf: error: invalid value 'bright' for '--ratio") && e.contains("auto"),
        "{e}"
    );
    let black = d.join("black.dng");
    let mut f = input.clone();
    f.mosaic.iter_mut().for_each(|v| *v = 512);
    write_dng(&f, &black, &DngOptions::default()).unwrap();
    let e = one_line_error(&pgrf(&[
        "enhance",
        s(&black),
        "--model",
        s(&m),
        "-o",
        s(&d.join("b.dng")),
    ]));
    assert!(
        e.contains("no signal above black") && e.contains("--ratio"),
        "{e}"
    );
}

/// A monochrome photo is restored by the built-in Bayer networks through
/// the 2x2 packing (four half-resolution images of one scene with the
/// same noise physics) and written back at full resolution as a one-sample
/// monochrome DNG. On a 256 x 256 grey scene of discs (seeded), darkened
/// 100x with the A7S2's ISO 1600 noise, the SPC model must lift the PSNR
/// against the clean frame well above the noisy input's (measured: 22.9 dB
/// in, 30.1 dB out on the same kind of scene; asserted: +5 dB and above
/// 27 dB).
#[test]
fn a_monochrome_photo_is_restored_and_stays_monochrome() {
    use pgrf_noise::capture::DarkCapture;
    use pgrf_noise::{CameraProfile, ModelKind};
    use rand::{Rng, SeedableRng};
    let d = scratch("mono");
    let (w, h, black, white, ratio) = (256usize, 256usize, 512.0f32, 16383u32, 100.0f32);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let mut scene = vec![0.25f32; w * h];
    for _ in 0..60 {
        let (cy, cx) = (
            rng.random_range(0.0..h as f32),
            rng.random_range(0.0..w as f32),
        );
        let (r, v) = (
            rng.random_range(5.0..40.0f32),
            rng.random_range(0.03..0.9f32),
        );
        for y in 0..h {
            for x in 0..w {
                if (y as f32 - cy).powi(2) + (x as f32 - cx).powi(2) < r * r {
                    scene[y * w + x] = v;
                }
            }
        }
    }
    let range = white as f32 - black;
    let mosaic = scene
        .iter()
        .map(|v| (black + v * 0.8 * range).round() as u16)
        .collect();
    let mut clean = RawFrame::from_mono(w, h, mosaic, black, white).unwrap();
    clean.exposure_s = Some(1.0);
    let dark = DarkCapture {
        profile: CameraProfile::built_in("sony-a7s2").unwrap(),
        model: ModelKind::Pgrf,
        iso: 1600,
        exposure_s: 0.01,
        ratio,
        seed: 3,
    }
    .take(&clean)
    .unwrap();
    let noisy = d.join("dark.dng");
    write_dng(&dark, &noisy, &DngOptions::default()).unwrap();
    let out = d.join("out.dng");
    let r = pgrf(&[
        "enhance",
        s(&noisy),
        "--model",
        "builtin:spc",
        "--ratio",
        "100",
        "-o",
        s(&out),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let back = decode_file(&out, &LevelOverrides::default()).unwrap();
    assert!(back.mono, "the result lost its monochrome layout");
    assert_eq!((back.width, back.height), (w, h));
    // PSNR on [0, 1] over every pixel (each frame normalised by its levels;
    // the noisy one amplified by the ratio, as the network is fed it).
    let norm = |f: &RawFrame, gain: f32| -> Vec<f32> {
        (f.mosaic.iter())
            .map(|&v| {
                ((v as f32 - f.black[0]) * gain / (f.white as f32 - f.black[0])).clamp(0.0, 1.0)
            })
            .collect()
    };
    let psnr = pgrf_nn::data::validation::psnr;
    let truth = norm(&clean, 1.0);
    let before = psnr(&norm(&dark, ratio), &truth);
    let after = psnr(&norm(&back, 1.0), &truth);
    eprintln!("monochrome restoration: PSNR {before:.2} dB in, {after:.2} dB out");
    assert!(
        after > before + 5.0 && after > 27.0,
        "PSNR {before:.2} dB in, {after:.2} dB out"
    );
    std::fs::remove_dir_all(&d).unwrap();
}

/// `--kernels` is handed to the run as configuration (no process-wide
/// switch): the model line names the operations chosen, and burn's and
/// pgrf's give the same DNG to within a DN or two of rounding.
#[test]
fn the_kernels_flag_reaches_the_run() {
    let d = scratch("kernels");
    let noisy = d.join("noisy.dng");
    dark_dng(&noisy, 96, 64, Cfa::Rggb, 5);
    let m = model(&d, false, None);
    let mut outs = Vec::new();
    for k in ["pgrf", "burn"] {
        let out = d.join(format!("{k}.dng"));
        let r = pgrf(&[
            "--kernels",
            k,
            "enhance",
            s(&noisy),
            "--model",
            s(&m),
            "--ratio",
            "20",
            "-o",
            s(&out),
        ]);
        let err = String::from_utf8_lossy(&r.stderr).to_string();
        assert!(r.status.success(), "{err}");
        assert!(err.contains(&format!("{k} operations")), "{err}");
        outs.push(
            decode_file(&out, &LevelOverrides::default())
                .unwrap()
                .mosaic,
        );
    }
    let worst = outs[0]
        .iter()
        .zip(&outs[1])
        .map(|(a, b)| (*a as i32 - *b as i32).abs())
        .max()
        .unwrap();
    assert!(worst <= 2, "burn and pgrf differ by {worst} DN");
}

/// Issue 53, item 1: `pgrf enhance FILE` with nothing else restores with
/// the built-in SPC, says so, and writes `FILE.pgrf.dng` (and with a bare
/// `--png`, `FILE.pgrf.png`) beside the input: the same bytes as naming
/// the model and the output. A folder without `-o`, or two inputs whose
/// results would share a name, are refused in one line, nothing written.
#[test]
fn with_no_flags_the_builtin_spc_writes_beside_the_input() {
    let d = scratch("noflags");
    let input = d.join("night.dng");
    dark_dng(&input, 64, 48, Cfa::Rggb, 4);
    let r = pgrf(&["enhance", s(&input), "--png"]);
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{err}");
    assert!(
        err.contains("(builtin:spc, the default without --model)"),
        "{err}"
    );
    assert_eq!(
        files_in(&d),
        ["night.dng", "night.pgrf.dng", "night.pgrf.png"]
    );
    let named = d.join("named.dng");
    let r = pgrf(&[
        "enhance",
        s(&input),
        "--model",
        "builtin:spc",
        "-o",
        s(&named),
        "--quiet",
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert!(std::fs::read(&named).unwrap() == std::fs::read(d.join("night.pgrf.dng")).unwrap());

    let folder = d.join("shoot");
    std::fs::create_dir(&folder).unwrap();
    dark_dng(&folder.join("a.dng"), 48, 32, Cfa::Rggb, 5);
    let e = one_line_error(&pgrf(&["enhance", s(&folder)]));
    assert!(e.contains("is a folder: give -o FOLDER"), "{e}");
    std::fs::copy(folder.join("a.dng"), folder.join("a.DNG")).unwrap();
    let (a, b) = (folder.join("a.dng"), folder.join("a.DNG"));
    let e = one_line_error(&pgrf(&["enhance", s(&a), s(&b)]));
    assert!(e.contains("would both be written to"), "{e}");
    assert_eq!(files_in(&folder), ["a.DNG", "a.dng"]);
}

/// Issue 53, item 2: a frame whose blind estimate finds no signal-dependent
/// noise (pgrf's noise-free chart) is restored at the quietest level the
/// estimate resolves, which is named, and comes out nearly unchanged; in a
/// batch beside a noisy frame both are written and the batch exits 0.
#[test]
fn a_frame_without_measurable_noise_passes_through_nearly_unchanged() {
    let d = scratch("quiet");
    let shoot = d.join("shoot");
    std::fs::create_dir(&shoot).unwrap();
    let chart = shoot.join("chart.dng");
    let r = pgrf(&[
        "chart",
        "-o",
        s(&chart),
        "--width",
        "192",
        "--height",
        "128",
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    dark_dng(&shoot.join("night.dng"), 64, 48, Cfa::Rggb, 6);
    let out = d.join("out");
    let r = pgrf(&["enhance", s(&shoot), "--ratio", "1", "-o", s(&out)]);
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{err}");
    assert!(
        err.contains("no signal-dependent noise in the frame")
            && err.contains("the smallest level the estimate resolves"),
        "{err}"
    );
    assert_eq!(files_in(&out), ["chart.dng", "night.dng"]);
    let r = pgrf(&["metrics", s(&out.join("chart.dng")), s(&chart)]);
    let text = String::from_utf8_lossy(&r.stdout);
    let psnr: f64 = text
        .lines()
        .find_map(|l| l.strip_prefix("PSNR"))
        .and_then(|v| v.trim().trim_end_matches("dB").trim().parse().ok())
        .unwrap_or_else(|| panic!("{text}"));
    // Measured 63.6 dB on the 256 x 192 chart: a near-identity.
    assert!(psnr > 50.0, "{psnr}");
}
