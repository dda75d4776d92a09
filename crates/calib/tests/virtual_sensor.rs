//! Virtual sensor -> DNG stacks -> calibrate: the estimators must recover the
//! truth that generated the frames.

use ndarray::{Array3, Zip};
use pgrf_calib::{calibrate, CalibrateInput, Calibration};
use pgrf_noise::sensor::{SensorSpec, VirtualSensor};
use pgrf_noise::{Capture, Components, DarkLaw, NoiseModel, ReadDist};
use pgrf_raw::{decode_bytes, write_dng, write_fits_frame, DngOptions, LevelOverrides};
use std::path::{Path, PathBuf};

fn scratch(name: &str) -> PathBuf {
    let d =
        std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("pgrf-calib-test-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

struct Stacks {
    bias: Vec<PathBuf>,
    dark: Vec<PathBuf>,
    flat: Vec<PathBuf>,
}

/// Takes a virtual sensor's frames and writes them as DNGs (or FITS) into
/// `dir/SUB`, each frame with the next seed.
struct Shooter<'a> {
    v: &'a VirtualSensor,
    dir: PathBuf,
    seed: u64,
    fits: bool,
}

impl Shooter<'_> {
    /// `n` frames of `electrons` of light at exposure `t`; a lamp `drift`
    /// makes frame i of the call (1 + drift i) times brighter.
    fn shoot(&mut self, sub: &str, n: usize, electrons: f32, t: f32, drift: f32) -> Vec<PathBuf> {
        let d = self.dir.join(sub);
        std::fs::create_dir_all(&d).unwrap();
        (0..n)
            .map(|i| {
                self.seed += 1;
                let e = electrons * (1.0 + drift * i as f32);
                let ext = if self.fits { "fits" } else { "dng" };
                let p = d.join(format!("{sub}_{electrons}_{t}_{i:03}.{ext}"));
                let f = self.v.frame(e, t, self.seed).unwrap();
                if self.fits {
                    write_fits_frame(&f, &p).unwrap();
                } else {
                    write_dng(&f, &p, &DngOptions::default()).unwrap();
                }
                p
            })
            .collect()
    }
}

/// Write bias (64 frames), dark (3 exposures x 16) and flat (2 levels x 16) stacks.
fn write_stacks(v: &VirtualSensor, dir: &Path, bias_frames: usize) -> Stacks {
    write_ladder(v, dir, bias_frames, &[1.0, 4.0, 16.0], 16)
}

/// Bias and flat stacks as [`write_stacks`], and `per` dark frames at each
/// of `exposures`.
fn write_ladder(
    v: &VirtualSensor,
    dir: &Path,
    bias_frames: usize,
    exposures: &[f32],
    per: usize,
) -> Stacks {
    let mut cam = Shooter {
        v,
        dir: dir.to_path_buf(),
        seed: 1000,
        fits: false,
    };
    let mut write =
        |sub: &str, n: usize, electrons: f32, t: f32| cam.shoot(sub, n, electrons, t, 0.0);
    let bias = write("bias", bias_frames, 0.0, 1.0 / 8000.0);
    let mut dark = Vec::new();
    for &t in exposures {
        dark.extend(write("dark", per, 0.0, t));
    }
    let mut flat = write("flat", 16, 2000.0, 0.01);
    flat.extend(write("flat", 16, 8000.0, 0.04));
    Stacks { bias, dark, flat }
}

fn sensor(law: DarkLaw) -> VirtualSensor {
    let mut s = SensorSpec::preset("a7s2-iso1600").unwrap();
    s.width = 128;
    s.height = 96;
    s.dark_law = law;
    s.dark_rate = 3.0;
    VirtualSensor::new(s).unwrap()
}

fn corr(a: &Array3<f32>, b: &Array3<f32>) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (
        a.iter().map(|&v| v as f64).sum::<f64>() / n,
        b.iter().map(|&v| v as f64).sum::<f64>() / n,
    );
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    Zip::from(a).and(b).for_each(|&x, &y| {
        let (x, y) = (x as f64 - ma, y as f64 - mb);
        sab += x * y;
        saa += x * x;
        sbb += y * y;
    });
    sab / (saa * sbb).sqrt()
}

#[test]
fn calibration_recovers_the_virtual_sensor() {
    let v = sensor(DarkLaw::Sqrt);
    let dir = scratch("recover");
    let s = write_stacks(&v, &dir, 64);
    let run = calibrate(
        &CalibrateInput {
            bias: s.bias.clone(),
            dark: s.dark.clone(),
            flat: s.flat.clone(),
            iso: Some(1600),
            tap_pixels: 256,
            ..Default::default()
        },
        &pgrf_core::NoProgress,
    )
    .unwrap();
    let m = &run.calibration.meta;
    // K within 2%.
    let k_true = v.spec.k as f64;
    assert!((m.k / k_true - 1.0).abs() < 0.02, "K {} vs {}", m.k, k_true);
    assert_eq!(m.k_method, pgrf_calib::GainMethod::PhotonTransfer);
    // Fixed pattern: RMSE against truth below the standard error of a mean of
    // 64 frames (temporal variance: read + row + quantisation), 5% slack for
    // the RMS itself being estimated from 12288 pixels.
    let fp = &run.calibration.maps.fixed_pattern;
    let n = fp.len() as f64;
    let rmse = (Zip::from(fp)
        .and(&v.bias)
        .fold(0.0, |a, &e, &t| a + ((e - t) as f64).powi(2))
        / n)
        .sqrt();
    let mean_var = v
        .sigma_read
        .iter()
        .map(|&s| (s as f64).powi(2))
        .sum::<f64>()
        / n
        + (v.spec.row_sigma as f64).powi(2)
        + 1.0 / 12.0;
    let se = (mean_var / 64.0).sqrt();
    assert!(rmse < 1.05 * se, "fixed-pattern RMSE {rmse} vs SE {se}");
    // Read-noise maps correlate with truth.
    let c = corr(&run.calibration.maps.sigma_read, &v.sigma_read);
    assert!(c > 0.9, "sigma correlation {c}");
    // Row noise and the dark law.
    assert!(
        (m.row_sigma / v.spec.row_sigma as f64 - 1.0).abs() < 0.15,
        "row sigma {}",
        m.row_sigma
    );
    assert_eq!(m.dark_law, Some(DarkLaw::Sqrt));
    // Hot pixels found (the sensor has ~1e-4 of them; at least those in the truth map).
    let hot_true: Vec<usize> = v
        .hot
        .iter()
        .enumerate()
        .filter(|(_, &h)| h > 0.0)
        .map(|(i, _)| i)
        .collect();
    let found = &run.calibration.maps.defects;
    for i in &hot_true {
        assert_eq!(found.as_slice().unwrap()[*i], 1.0, "hot pixel {i} missed");
    }
    // Per-pixel read noise is Gaussian (PPCC near 1 for 64 samples).
    assert!(
        m.ppcc_pixel_median.unwrap() > 0.97,
        "{:?}",
        m.ppcc_pixel_median
    );

    // The file round-trips and converts to noise-model maps.
    let path = dir.join("calib.safetensors");
    run.calibration.save(&path).unwrap();
    let back = Calibration::load(&path).unwrap();
    assert_eq!(back.meta, run.calibration.meta);
    assert_eq!(back.maps.sigma_read, run.calibration.maps.sigma_read);
    assert!(back
        .check_matches(&m.make, &m.model, Some(1600), false)
        .is_ok());
    assert!(back
        .check_matches(&m.make, &m.model, Some(3200), false)
        .is_err());
    assert!(back
        .check_matches("Sony", "ILCE-7SM2", Some(1600), false)
        .is_err());
    assert!(back
        .check_matches("Sony", "ILCE-7SM2", Some(3200), true)
        .is_ok());

    // Dark shading for a 4 s exposure: fixed pattern + K x rate x sqrt(4),
    // computed here from the maps; at t = 0 it is the fixed pattern alone.
    let shading = back.dark_shading_dn(4.0).unwrap();
    let expect = Zip::from(&back.maps.fixed_pattern)
        .and(&back.maps.dark_rate)
        .map_collect(|&f, &r| f + (r as f64 * 2.0 * m.k) as f32);
    let worst = Zip::from(&shading)
        .and(&expect)
        .fold(0.0f32, |w, &a, &b| w.max((a - b).abs()));
    assert!(worst < 1e-4, "dark shading differs by {worst} DN");
    assert_eq!(back.dark_shading_dn(0.0).unwrap(), back.maps.fixed_pattern);
    assert!(back.dark_shading_dn(-1.0).is_err());

    // Per-pixel calibration reproduces the sensor's per-pixel variance better
    // than the global ("noD") one: synthesise 64 dark frames with each.
    let maps = back.to_pixel_maps().unwrap();
    let model = |global: bool| NoiseModel {
        k: m.k as f32,
        read: ReadDist::Gaussian,
        maps: if global { maps.global() } else { maps.clone() },
        row_sigma: m.row_sigma as f32,
        quant_step: 1.0,
        components: Components::parse("G,H,Q,F").unwrap(),
        dn_range: 16383.0 - 512.0,
        black: Some(512.0),
        bank: None,
    };
    let truth_var = v.sigma_read.mapv(|s| s * s + v.spec.row_sigma.powi(2));
    let zeros = Array3::<f32>::zeros(v.bias.raw_dim());
    let mut err = [0.0f64; 2];
    for (slot, global) in [false, true].into_iter().enumerate() {
        let md = model(global);
        let mut acc = Vec::new();
        for seed in 0..64u64 {
            let out = md
                .sample(
                    zeros.view(),
                    &Capture {
                        ratio: 1.0,
                        exposure_s: 0.0,
                        plane_rows: [0, 0, 1, 1],
                        seed,
                    },
                )
                .unwrap();
            acc.push(out.mapv(|x| x * (16383.0 - 512.0)));
        }
        let mean = acc
            .iter()
            .fold(Array3::<f32>::zeros(zeros.raw_dim()), |a, b| a + b)
            / 64.0;
        let var = acc
            .iter()
            .fold(Array3::<f32>::zeros(zeros.raw_dim()), |a, b| {
                a + &(b - &mean).mapv(|d| d * d)
            })
            / 63.0;
        err[slot] = Zip::from(&var)
            .and(&truth_var)
            .fold(0.0, |a, &x, &t| a + ((x - t) as f64).powi(2))
            / n;
    }
    assert!(
        err[0] < 0.6 * err[1],
        "per-pixel MSE {} vs global {}",
        err[0],
        err[1]
    );
}

#[test]
fn linear_dark_current_is_recognised() {
    let v = sensor(DarkLaw::Linear);
    let dir = scratch("linear");
    let s = write_stacks(&v, &dir, 16);
    let run = calibrate(
        &CalibrateInput {
            bias: s.bias,
            dark: s.dark,
            flat: s.flat,
            iso: None,
            tap_pixels: 0,
            ..Default::default()
        },
        &pgrf_core::NoProgress,
    )
    .unwrap();
    assert_eq!(run.calibration.meta.dark_law, Some(DarkLaw::Linear));
    let d = run.dark.unwrap();
    assert!(d.r2_linear_global > d.r2_sqrt_global);
    // Mean rate in electrons per second, hot pixels included.
    let want = v.dark_rate.mean().unwrap() as f64;
    assert!(
        (d.rate_mean / want - 1.0).abs() < 0.1,
        "rate {} vs {}",
        d.rate_mean,
        want
    );
}

/// A dark ladder as people shoot it, one frame at each of six exposures
/// (10 to 300 s): the estimator takes it, picks the true law among a t,
/// a sqrt(t) and each with an offset c, and recovers the mean rate and the
/// offset K c within 5 % (the issue asks 10 %; seen: within 1 %).
#[test]
fn one_dark_frame_per_exposure_recovers_the_law_and_rate() {
    let ladder = [10.0, 20.0, 30.0, 60.0, 150.0, 300.0];
    for (law, rate, offset_e, name) in [
        (DarkLaw::Linear, 3.0, 0.0, "linear"),
        (DarkLaw::Linear, 3.0, 300.0, "linear + c"),
        (DarkLaw::Sqrt, 10.0, 0.0, "sqrt"),
        (DarkLaw::Sqrt, 10.0, 300.0, "sqrt + c"),
    ] {
        let mut spec = SensorSpec::preset("a7s2-iso1600").unwrap();
        spec.width = 128;
        spec.height = 96;
        spec.dark_law = law;
        spec.dark_rate = rate;
        spec.dark_offset = offset_e;
        let v = VirtualSensor::new(spec).unwrap();
        let dir = scratch(&format!("ladder-{}", name.replace([' ', '+'], "")));
        let s = write_ladder(&v, &dir, 16, &ladder, 1);
        let run = calibrate(
            &CalibrateInput {
                bias: s.bias,
                dark: s.dark,
                flat: s.flat,
                ..Default::default()
            },
            &pgrf_core::NoProgress,
        )
        .unwrap_or_else(|e| panic!("{name}: {e}"));
        let m = &run.calibration.meta;
        assert_eq!(
            (m.dark_law, m.dark_offset),
            (Some(law), offset_e > 0.0),
            "{name}"
        );
        assert_eq!(m.dark_frames, vec![1; 6], "{name}");
        let d = run.dark.as_ref().unwrap();
        let want = v.dark_rate.mean().unwrap() as f64;
        assert!(
            (d.rate_mean / want - 1.0).abs() < 0.05,
            "{name}: rate {} vs {want}",
            d.rate_mean
        );
        if offset_e > 0.0 {
            let want_c = v.spec.k as f64 * offset_e as f64;
            let got = m.dark_offset_mean.unwrap();
            assert!(
                (got / want_c - 1.0).abs() < 0.05,
                "{name}: offset {got} DN vs {want_c}"
            );
            assert!(run.calibration.maps.dark_offset.is_some());
            // What enhance subtracts from a 60 s exposure: K rate g(60) + c
            // above the fixed pattern; a zero-length frame has no offset.
            let c = &run.calibration;
            let mean = |t: f64| c.dark_shading_dn(t).unwrap().mean().unwrap() as f64;
            let fp = c.maps.fixed_pattern.mean().unwrap() as f64;
            let expect = m.k * d.rate_mean * law.electrons(1.0, 60.0) + got;
            assert!(
                ((mean(60.0) - fp) / expect - 1.0).abs() < 0.01,
                "{name}: shading {} vs {expect}",
                mean(60.0) - fp
            );
            assert!((mean(0.0) - fp).abs() < 1e-3, "{name}");
        } else {
            assert!(m.dark_offset_mean.is_none() && run.calibration.maps.dark_offset.is_none());
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

/// A flat lamp that brightens by 0.3 % per frame: the pair method (EMVA
/// 1288's temporal variance from frame differences) keeps K within 2 % of
/// the truth, while each pixel's variance over the stack, the estimate
/// without it, is biased by the drift (here by more than 50 %).
#[test]
fn lamp_drift_does_not_bias_the_gain() {
    let v = sensor(DarkLaw::Sqrt);
    let dir = scratch("drift");
    let mut cam = Shooter {
        v: &v,
        dir: dir.clone(),
        seed: 7000,
        fits: false,
    };
    let mut write = |sub: &str, n, e, t, drift| cam.shoot(sub, n, e, t, drift);
    let bias = write("bias", 16, 0.0, 1.0 / 8000.0, 0.0);
    let mut flat = write("flat", 16, 2000.0, 0.01, 0.003);
    flat.extend(write("flat", 16, 6000.0, 0.04, 0.003));
    let run = calibrate(
        &CalibrateInput {
            bias,
            flat,
            ..Default::default()
        },
        &pgrf_core::NoProgress,
    )
    .unwrap();
    let truth = v.spec.k as f64;
    let k = run.calibration.meta.k;
    let stacked = run.gain.k_without_pairs;
    assert!((k / truth - 1.0).abs() < 0.02, "K {k} vs {truth}");
    // A clean sensor has no cold pixel and no defective column.
    let m = &run.calibration.meta;
    assert_eq!((m.cold_pixels, m.defect_columns), (0, 0));
    // A lamp's slow drift spreads the frames evenly: none is named odd.
    assert!(
        run.calibration.meta.warnings.is_empty(),
        "{:?}",
        run.calibration.meta.warnings
    );
    assert!(
        stacked / truth - 1.0 > 0.5,
        "K without pairs {stacked} vs {truth}"
    );
    // The drift is measured: 16 frames rising 0.3 % each have a relative
    // spread of 0.3 % x sqrt((16^2 - 1) / 12) = 1.38 %.
    for l in &run.gain.levels {
        assert!((l.drift / 0.01383 - 1.0).abs() < 0.1, "drift {}", l.drift);
    }
    // The per-pixel gain map is normalised per frame too: its mean (the
    // median of a variance over 16 frames sits 4 % below its mean) is
    // within 3 % of the truth, where without the correction it is 2x.
    let map = run.calibration.maps.gain.as_ref().unwrap();
    let finite: Vec<f64> = map
        .iter()
        .filter(|v| v.is_finite())
        .map(|&v| v as f64)
        .collect();
    let km = finite.iter().sum::<f64>() / finite.len() as f64;
    assert!(
        (km / truth - 1.0).abs() < 0.03,
        "gain map mean {km} vs {truth}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A readout whose offset wanders by 1 DN from frame to frame: the drift
/// and the row noise are told apart (each within 15 %), and neither
/// inflates the read noise.
#[test]
fn frame_offset_drift_is_not_row_noise() {
    let mut spec = SensorSpec::preset("a7s2-iso1600").unwrap();
    spec.width = 128;
    spec.height = 96;
    spec.frame_offset_sigma = 1.0;
    let v = VirtualSensor::new(spec).unwrap();
    let dir = scratch("frameoffset");
    std::fs::create_dir_all(dir.join("flat")).unwrap();
    let bias: Vec<PathBuf> = (0..64u64)
        .map(|i| {
            let p = dir.join(format!("bias_{i:03}.dng"));
            write_dng(
                &v.frame(0.0, 1.0 / 8000.0, 500 + i).unwrap(),
                &p,
                &DngOptions::default(),
            )
            .unwrap();
            p
        })
        .collect();
    let flat: Vec<PathBuf> = (0..4u64)
        .map(|i| {
            let p = dir.join("flat").join(format!("flat_{i}.dng"));
            write_dng(
                &v.frame(4000.0, 0.02, 900 + i).unwrap(),
                &p,
                &DngOptions::default(),
            )
            .unwrap();
            p
        })
        .collect();
    let run = calibrate(
        &CalibrateInput {
            bias,
            flat,
            ..Default::default()
        },
        &pgrf_core::NoProgress,
    )
    .unwrap();
    let m = &run.calibration.meta;
    let (row, frame) = (m.row_sigma, m.frame_offset_sigma.unwrap());
    let want_row = v.spec.row_sigma as f64;
    assert!(
        (row / want_row - 1.0).abs() < 0.15,
        "row {row} vs {want_row}"
    );
    assert!((frame - 1.0).abs() < 0.15, "frame offset {frame} vs 1");
    let read = pgrf_core::stats::median_finite(&v.sigma_read);
    assert!(
        (m.read_sigma_median / read - 1.0).abs() < 0.05,
        "read {} vs {read}",
        m.read_sigma_median
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A bias frame read 4 DN above the others is named (and kept) by default,
/// and dropped with `reject`, which brings the read noise back to the
/// clean stack's.
#[test]
fn an_odd_frame_is_named_and_can_be_rejected() {
    let v = sensor(DarkLaw::Sqrt);
    let dir = scratch("odd");
    let s = write_stacks(&v, &dir, 16);
    // Bias frame 5 shifted by 4 DN.
    let odd = &s.bias[5];
    let mut f = pgrf_raw::decode_file(odd, &Default::default()).unwrap();
    f.mosaic.iter_mut().for_each(|x| *x += 4);
    write_dng(&f, odd, &DngOptions::default()).unwrap();
    let input = CalibrateInput {
        bias: s.bias.clone(),
        flat: s.flat.clone(),
        ..Default::default()
    };
    let kept = calibrate(&input, &pgrf_core::NoProgress).unwrap();
    let w = &kept.calibration.meta.warnings;
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].contains(&odd.display().to_string()) && w[0].contains("mean") && w[0].contains("kept"),
        "{w:?}"
    );
    let dropped = calibrate(
        &CalibrateInput {
            reject: true,
            ..input
        },
        &pgrf_core::NoProgress,
    )
    .unwrap();
    let m = &dropped.calibration.meta;
    assert!(m.warnings.is_empty(), "{:?}", m.warnings);
    assert_eq!(m.rejected_frames.len(), 1);
    assert_eq!(m.bias_frames, 15);
    // The odd frame adds (4 - 4/16)^2 / 16 ~ 0.9 DN^2 to every pixel's
    // variance while kept.
    let read = pgrf_core::stats::median_finite(&v.sigma_read);
    let (with, without) = (kept.calibration.meta.read_sigma_median, m.read_sigma_median);
    assert!(with > without, "{with} vs {without}");
    assert!((without / read - 1.0).abs() < 0.05, "{without} vs {read}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// EMVA 1288's non-uniformity: with flats that lose 20 % of their light
/// towards the corners and 12 bias pixels stuck 200 DN high, the plain
/// PRNU and DSNU measure the shading and the outliers, the high-pass ones
/// (5 x 5 box, outliers excluded) the sensor's truth (PRNU 1 %, DSNU
/// 1.5 DN) within 15 %.
#[test]
fn highpass_non_uniformity_leaves_out_shading_and_hot_pixels() {
    let mut spec = SensorSpec::preset("a7s2-iso1600").unwrap();
    spec.width = 256;
    spec.height = 192;
    spec.vignetting = 0.2;
    let v = VirtualSensor::new(spec).unwrap();
    let dir = scratch("highpass");
    let s = write_stacks(&v, &dir, 32);
    for f in &s.bias {
        let mut fr = pgrf_raw::decode_file(f, &Default::default()).unwrap();
        for k in 0..12 {
            fr.mosaic[(40 + 9 * k) * 256 + 30 + 17 * k] += 200;
        }
        write_dng(&fr, f, &DngOptions::default()).unwrap();
    }
    let run = calibrate(
        &CalibrateInput {
            bias: s.bias,
            flat: s.flat,
            ..Default::default()
        },
        &pgrf_core::NoProgress,
    )
    .unwrap();
    let m = &run.calibration.meta;
    let (prnu, prnu_hp) = (m.prnu.unwrap(), m.prnu_highpass.unwrap());
    let (dsnu, dsnu_hp) = (m.dsnu, m.dsnu_highpass.unwrap());
    assert!(
        (prnu_hp / 0.01 - 1.0).abs() < 0.15,
        "PRNU high-pass {prnu_hp}"
    );
    assert!(
        prnu > 3.0 * prnu_hp,
        "plain PRNU {prnu} should hold the shading"
    );
    assert!(
        (dsnu_hp / 1.5 - 1.0).abs() < 0.15,
        "DSNU high-pass {dsnu_hp}"
    );
    assert!(
        dsnu > 1.5 * dsnu_hp,
        "plain DSNU {dsnu} should hold the stuck pixels"
    );
    // K's statistical uncertainty is stated, and small against K.
    let ks = m.k_sigma.unwrap();
    assert!(ks > 0.0 && ks < 0.01 * m.k, "K sigma {ks}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Flats run up to saturation, as EMVA 1288 has them: the clipped level is
/// left out of K and marks the saturation capacity, and the levels below
/// give the linearity error (the virtual sensor is linear).
#[test]
fn flats_up_to_saturation_give_capacity_and_linearity() {
    let v = sensor(DarkLaw::Sqrt);
    let dir = scratch("saturation");
    let mut cam = Shooter {
        v: &v,
        dir: dir.clone(),
        seed: 9000,
        fits: false,
    };
    let mut frames = |n, e, t| cam.shoot("f", n, e, t, 0.0);
    let bias = frames(16, 0.0, 1.0 / 8000.0);
    let mut flat = Vec::new();
    for e in [1000.0f32, 3000.0, 6000.0, 9000.0, 14000.0] {
        flat.extend(frames(8, e, e / 1e5));
    }
    let run = calibrate(
        &CalibrateInput {
            bias,
            flat,
            ..Default::default()
        },
        &pgrf_core::NoProgress,
    )
    .unwrap();
    let m = &run.calibration.meta;
    let truth = v.spec.k as f64;
    assert_eq!(run.gain.saturated.len(), 1);
    assert_eq!(run.gain.levels.len(), 4);
    assert!((m.k / truth - 1.0).abs() < 0.02, "K {} vs {truth}", m.k);
    // Between the brightest unclipped level and the range over K.
    let full = v.spec.dn_range() as f64 / truth;
    let sat = m.saturation_capacity_e.unwrap();
    assert!(
        sat > 0.97 * 9000.0 && sat < 1.02 * full,
        "saturation {sat} e- (range {full})"
    );
    let le = m.linearity_error.unwrap();
    assert!(le < 0.005, "linearity error {le}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A pixel stuck 300 DN low is found (coded 3); a column whose amplifier
/// reads 3 DN high in the bias only is not a defect (subtracting the bias
/// or the fixed pattern removes it: replacing its pixels would only blur),
/// so nothing is coded 4.
#[test]
fn cold_pixels_and_defective_columns_are_mapped() {
    let v = sensor(DarkLaw::Sqrt);
    let dir = scratch("columns");
    let s = write_stacks(&v, &dir, 16);
    let s_bias0 = s.bias[0].clone();
    // Sensor column 41 (odd: plane G1 or B of RGGB, packed column 20);
    // sensor (30, 60): plane R, packed (15, 30).
    for f in &s.bias {
        let mut fr = pgrf_raw::decode_file(f, &Default::default()).unwrap();
        for y in 0..96 {
            fr.mosaic[y * 128 + 41] += 3;
        }
        fr.mosaic[30 * 128 + 60] -= 300;
        write_dng(&fr, f, &DngOptions::default()).unwrap();
    }
    let run = calibrate(
        &CalibrateInput {
            bias: s.bias,
            flat: s.flat,
            ..Default::default()
        },
        &pgrf_core::NoProgress,
    )
    .unwrap();
    let m = &run.calibration.meta;
    let d = &run.calibration.maps.defects;
    assert_eq!(d[[0, 15, 30]], 3.0, "the cold pixel");
    assert_eq!(m.cold_pixels, 1);
    // Sensor column 41 (G1 and B) is high in the bias only.
    assert_eq!(m.defect_columns, 0, "{:?}", m);
    assert_eq!(d.iter().filter(|&&c| c == 4.0).count(), 0);
    // It is in the fixed pattern, which subtraction removes: its column
    // mean stands 3 DN above its neighbours' (within 0.5).
    let fp = &run.calibration.maps.fixed_pattern;
    let mean = |j: usize| fp.slice(ndarray::s![1, .., j]).mean().unwrap();
    let step = mean(20) - (mean(19) + mean(21)) / 2.0;
    assert!((step - 3.0).abs() < 0.5, "{step}");
    // Cosmetic correction: the cold pixel of a bias frame becomes the
    // median of its eight same-colour neighbours; the column is left.
    let mut fr = pgrf_raw::decode_file(&s_bias0, &Default::default()).unwrap();
    let mut near: Vec<u16> = [
        (-2i32, -2i32),
        (-2, 0),
        (-2, 2),
        (0, -2),
        (0, 2),
        (2, -2),
        (2, 0),
        (2, 2),
    ]
    .iter()
    .map(|(dy, dx)| fr.mosaic[((30 + dy) * 128 + 60 + dx) as usize])
    .collect();
    near.sort_unstable();
    let want = (near[3] as u32 + near[4] as u32).div_ceil(2) as u16;
    let column_before: Vec<u16> = (0..96).map(|y| fr.mosaic[y * 128 + 41]).collect();
    assert_eq!(run.calibration.correct_defects(&mut fr), 1);
    assert_eq!(fr.mosaic[30 * 128 + 60], want);
    let column_after: Vec<u16> = (0..96).map(|y| fr.mosaic[y * 128 + 41]).collect();
    assert_eq!(column_before, column_after);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Frames record their temperature: darks taken at -5 °C among bias and
/// flats at -10 °C are refused with a dark named, unless the tolerance
/// allows it; the record keeps the frames' median temperature.
#[test]
fn frames_of_another_temperature_are_refused() {
    let mut spec = SensorSpec::preset("a7s2-iso1600").unwrap();
    spec.width = 64;
    spec.height = 48;
    spec.temperature_c = Some(-10.0);
    let cold = VirtualSensor::new(spec.clone()).unwrap();
    spec.temperature_c = Some(-5.0);
    let warm = VirtualSensor::new(spec).unwrap();
    let dir = scratch("temperature");
    let s = write_stacks(&cold, &dir, 16);
    let warm_dark = write_ladder(&warm, &dir.join("warm"), 2, &[1.0, 4.0, 16.0], 4).dark;
    let input = CalibrateInput {
        bias: s.bias,
        flat: s.flat,
        dark: warm_dark,
        ..Default::default()
    };
    let e = calibrate(&input, &pgrf_core::NoProgress)
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("warm/dark/") && e.contains("-5.0 °C") && e.contains("median is -10.0 °C"),
        "{e}"
    );
    let run = calibrate(
        &CalibrateInput {
            temperature_tolerance: Some(6.0),
            ..input
        },
        &pgrf_core::NoProgress,
    )
    .unwrap();
    assert_eq!(run.calibration.meta.temperature_c, Some(-10.0));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 18's whole case at once: a sensor with lamp drift (0.3 % per flat
/// frame), whole-frame offset drift (0.5 DN), vignetting (20 %), a linear
/// dark law with an offset (300 e-) shot as a ladder of one frame per
/// exposure, flats up to saturation, and hot pixels. Every EMVA figure
/// against the truth, with the tolerance stated at each assertion.
#[test]
fn every_emva_figure_holds_on_a_drifting_ccd_like_sensor() {
    let mut spec = SensorSpec::preset("a7s2-iso1600").unwrap();
    spec.width = 256;
    spec.height = 192;
    spec.dark_law = DarkLaw::Linear;
    spec.dark_rate = 3.0;
    spec.dark_offset = 300.0;
    spec.frame_offset_sigma = 0.5;
    spec.vignetting = 0.2;
    let v = VirtualSensor::new(spec).unwrap();
    let dir = scratch("emva");
    let mut cam = Shooter {
        v: &v,
        dir: dir.clone(),
        seed: 20_000,
        fits: false,
    };
    let mut frames = |sub: &str, n, e, t, drift| cam.shoot(sub, n, e, t, drift);
    let bias = frames("bias", 64, 0.0, 1.0 / 8000.0, 0.0);
    let mut flat = Vec::new();
    // Exposures of 0.5 s and more, so the dark offset (built within the
    // first 0.05 s) is a constant under the flats, not a bend in them.
    for e in [1000.0f32, 3000.0, 6000.0, 9000.0, 14000.0] {
        flat.extend(frames("flat", 8, e, e / 2e3, 0.003));
    }
    let mut dark = Vec::new();
    for t in [10.0f32, 20.0, 30.0, 60.0, 150.0, 300.0] {
        dark.extend(frames("dark", 1, 0.0, t, 0.0));
    }
    let run = calibrate(
        &CalibrateInput {
            bias,
            dark,
            flat,
            ..Default::default()
        },
        &pgrf_core::NoProgress,
    )
    .unwrap();
    let m = &run.calibration.meta;
    // The report's summary, for `--nocapture`.
    for (q, val, unit) in run.summary() {
        eprintln!("{q}: {val} {unit}");
    }
    let sp = &v.spec;
    let rel = |got: f64, want: f64| (got / want - 1.0).abs();
    // System gain: 2 %.
    assert!(rel(m.k, sp.k as f64) < 0.02, "K {} vs {}", m.k, sp.k);
    // Read noise (median): 5 %; row noise and frame offset drift: 15 %.
    let read = pgrf_core::stats::median_finite(&v.sigma_read);
    assert!(
        rel(m.read_sigma_median, read) < 0.05,
        "read {}",
        m.read_sigma_median
    );
    assert!(
        rel(m.row_sigma, sp.row_sigma as f64) < 0.15,
        "row {}",
        m.row_sigma
    );
    let fo = m.frame_offset_sigma.unwrap();
    assert!(rel(fo, 0.5) < 0.15, "frame offset {fo}");
    // The DNG NoiseProfile pair: S = K / range (2 %), O = the dark temporal
    // variance (mean read variance + row + frame offset + 1/12 DN^2 of
    // rounding) / range^2 (5 %).
    let range = (sp.dn_range()) as f64;
    let [s, o] = run.noise_profile();
    assert!(rel(s, sp.k as f64 / range) < 0.02, "S {s}");
    let read_var = v
        .sigma_read
        .iter()
        .map(|&x| (x as f64).powi(2))
        .sum::<f64>()
        / v.sigma_read.len() as f64;
    let dark_var = read_var + (sp.row_sigma as f64).powi(2) + 0.25 + 1.0 / 12.0;
    assert!(
        rel(o, dark_var / (range * range)) < 0.05,
        "O {o} vs {}",
        dark_var / (range * range)
    );
    // DSNU and PRNU, EMVA high-pass: 10 % and 15 % (design: 1.5 DN, 1 %).
    assert!(
        rel(m.dsnu_highpass.unwrap(), 1.5) < 0.10,
        "DSNU {:?}",
        m.dsnu_highpass
    );
    assert!(
        rel(m.prnu_highpass.unwrap(), 0.01) < 0.15,
        "PRNU {:?}",
        m.prnu_highpass
    );
    // Dark law, rate (e-/s, hot pixels included) and offset: 5 %.
    assert_eq!((m.dark_law, m.dark_offset), (Some(DarkLaw::Linear), true));
    let rate = v.dark_rate.mean().unwrap() as f64;
    assert!(
        rel(m.dark_rate_mean.unwrap(), rate) < 0.05,
        "rate {:?}",
        m.dark_rate_mean
    );
    let c = m.dark_offset_mean.unwrap();
    assert!(rel(c, sp.k as f64 * 300.0) < 0.05, "offset {c}");
    // Saturation capacity between the brightest unclipped level and the
    // range over K; linearity error below 0.5 % (the sensor is linear).
    let sat = m.saturation_capacity_e.unwrap();
    assert!(
        sat > 0.97 * 9000.0 && sat < 1.02 * sp.dn_range() as f64 / sp.k as f64,
        "{sat}"
    );
    assert!(
        m.linearity_error.unwrap() < 0.005,
        "{:?}",
        m.linearity_error
    );
    // Every true hot pixel is flagged, and few others are.
    let d = &run.calibration.maps.defects;
    let truth: Vec<usize> = v
        .hot
        .iter()
        .enumerate()
        .filter(|(_, &h)| h > 0.0)
        .map(|(i, _)| i)
        .collect();
    assert!(!truth.is_empty());
    for &i in &truth {
        assert_eq!(d.as_slice().unwrap()[i], 1.0, "hot pixel {i} missed");
    }
    assert!(
        m.hot_pixels <= 2 * truth.len() + 5,
        "{} flagged, {} true",
        m.hot_pixels,
        truth.len()
    );
    assert!(m.warnings.is_empty(), "{:?}", m.warnings);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// One flat level: K from eq. 3.15 with a warning that nothing checks the
/// sensor's linearity, in the record (and so in the report).
/// The astronomer's case: a cooled monochrome CCD (linear dark current with
/// an offset, at -10 °C), its stacks as 16-bit FITS files with one dark
/// frame per exposure. The calibration is a monochrome one (no CFA in the
/// record), its figures hold, and the masters come out as FITS that read
/// back monochrome with the stacks' means.
#[test]
fn a_monochrome_fits_camera_calibrates_with_fits_masters() {
    let mut spec = SensorSpec::preset("a7s2-iso1600").unwrap();
    spec.width = 128;
    spec.height = 96;
    spec.mono = true;
    spec.dark_law = DarkLaw::Linear;
    spec.dark_rate = 3.0;
    spec.dark_offset = 100.0;
    spec.temperature_c = Some(-10.0);
    let v = VirtualSensor::new(spec).unwrap();
    let dir = scratch("monofits");
    let mut cam = Shooter {
        v: &v,
        dir: dir.clone(),
        seed: 31_000,
        fits: true,
    };
    let bias = cam.shoot("bias", 32, 0.0, 1.0 / 8000.0, 0.0);
    let bias0 = bias[0].clone();
    let mut flat = cam.shoot("flat", 8, 2000.0, 1.0, 0.0);
    flat.extend(cam.shoot("flat", 8, 8000.0, 4.0, 0.0));
    let mut dark = Vec::new();
    for t in [10.0f32, 20.0, 30.0, 60.0, 150.0, 300.0] {
        dark.extend(cam.shoot("dark", 1, 0.0, t, 0.0));
    }
    let run = calibrate(
        &CalibrateInput {
            bias,
            dark,
            flat,
            masters: true,
            ..Default::default()
        },
        &pgrf_core::NoProgress,
    )
    .unwrap();
    let m = &run.calibration.meta;
    assert_eq!(m.layout(), "mono");
    assert!(run.key.fits);
    assert_eq!(m.temperature_c, Some(-10.0));
    let k = v.spec.k as f64;
    assert!((m.k / k - 1.0).abs() < 0.03, "K {} vs {k}", m.k);
    assert_eq!((m.dark_law, m.dark_offset), (Some(DarkLaw::Linear), true));
    let rate = v.dark_rate.mean().unwrap() as f64;
    assert!(
        (m.dark_rate_mean.unwrap() / rate - 1.0).abs() < 0.10,
        "rate {:?} vs {rate}",
        m.dark_rate_mean
    );
    // Masters: bias, six darks, two flats, each FITS that decodes
    // monochrome with the stack's mean (to the DN it is rounded to).
    assert_eq!(run.masters.len(), 9);
    for master in &run.masters {
        let bytes = master.fits(&run.key, m.k, m.temperature_c).unwrap();
        let f = decode_bytes(Path::new("master.fits"), &bytes, &LevelOverrides::default()).unwrap();
        assert!(f.mono, "{}", master.name);
        assert_eq!(f.exposure_s, Some(master.exposure_s));
        let packed = pgrf_raw::pack_u16(&f).unwrap();
        for (a, b) in packed.iter().zip(master.mean.iter()) {
            assert!((*a as f32 - b).abs() <= 0.5, "{}: {a} vs {b}", master.name);
        }
    }
    mono_cosmetic_correction_uses_direct_neighbours(&run.calibration, &bias0);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Cosmetic correction of a monochrome frame: each defective pixel becomes
/// the median of its eight direct neighbours (one colour: no reason to
/// skip a photosite). On a frame whose value depends on the row and column
/// parity (1000 + 10 (r mod 2) + 20 (c mod 2)), the direct neighbours of an
/// even-even pixel hold 1010, 1020 and 1030 (median 1025) while the
/// same-parity ones a Bayer correction would take hold 1000: the two rules
/// give different numbers, and the test pins the direct one.
fn mono_cosmetic_correction_uses_direct_neighbours(c: &Calibration, path: &Path) {
    let mut f = pgrf_raw::decode_file(path, &Default::default()).unwrap();
    assert!(f.mono);
    let (h, w) = (f.height, f.width);
    let value = |r: usize, c: usize| 1000 + 10 * (r % 2) as u16 + 20 * (c % 2) as u16;
    for r in 0..h {
        for col in 0..w {
            f.mosaic[r * w + col] = value(r, col);
        }
    }
    let d = &c.maps.defects;
    let offsets = f.cfa.offsets();
    let flagged: Vec<(usize, usize)> = d
        .indexed_iter()
        .filter(|(_, &v)| v == 1.0 || v == 2.0 || v == 3.0)
        .map(|((p, i, j), _)| (2 * i + offsets[p].0, 2 * j + offsets[p].1))
        .collect();
    assert!(!flagged.is_empty(), "the virtual sensor has a hot pixel");
    let want: Vec<u16> = flagged
        .iter()
        .map(|&(r, col)| {
            let mut near: Vec<u16> = (-1i64..=1)
                .flat_map(|dy| (-1i64..=1).map(move |dx| (dy, dx)))
                .filter(|&d| d != (0, 0))
                .map(|(dy, dx)| (r as i64 + dy, col as i64 + dx))
                .filter(|&(y, x)| y >= 0 && x >= 0 && y < h as i64 && x < w as i64)
                .filter(|&(y, x)| !flagged.contains(&(y as usize, x as usize)))
                .map(|(y, x)| value(y as usize, x as usize))
                .collect();
            near.sort_unstable();
            let n = near.len();
            if n % 2 == 1 {
                near[n / 2]
            } else {
                (near[n / 2 - 1] as u32 + near[n / 2] as u32).div_ceil(2) as u16
            }
        })
        .collect();
    assert_eq!(c.correct_defects(&mut f), flagged.len());
    for (&(r, col), &v) in flagged.iter().zip(&want) {
        assert_eq!(f.mosaic[r * w + col], v, "defect at ({r}, {col})");
        // Never the same-parity value alone: direct neighbours differ in
        // parity, so their median is not the pixel's own parity class.
        assert_ne!(v, value(r, col), "defect at ({r}, {col})");
    }
}

#[test]
fn one_flat_level_warns() {
    let v = sensor(DarkLaw::Sqrt);
    let dir = scratch("onelevel");
    let s = write_stacks(&v, &dir, 16);
    let one: Vec<PathBuf> = s.flat.iter().take(16).cloned().collect();
    let run = calibrate(
        &CalibrateInput {
            bias: s.bias,
            flat: one,
            ..Default::default()
        },
        &pgrf_core::NoProgress,
    )
    .unwrap();
    let m = &run.calibration.meta;
    assert_eq!(m.k_method, pgrf_calib::GainMethod::VarOverMean);
    assert_eq!(m.warnings.len(), 1);
    assert!(
        m.warnings[0].contains("no photon-transfer fit"),
        "{:?}",
        m.warnings
    );
    assert!((m.k / v.spec.k as f64 - 1.0).abs() < 0.05, "K {}", m.k);
    assert!(run
        .summary()
        .iter()
        .any(|(q, v, _)| q == "Warning" && v.contains("linearity")));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_stacks_are_refused_with_the_file_named() {
    let v = sensor(DarkLaw::Sqrt);
    let dir = scratch("bad");
    let s = write_stacks(&v, &dir, 4);
    let run = |bias: Vec<PathBuf>, iso: Option<u32>| {
        calibrate(
            &CalibrateInput {
                bias,
                dark: s.dark.clone(),
                flat: s.flat.clone(),
                iso,
                tap_pixels: 0,
                ..Default::default()
            },
            &pgrf_core::NoProgress,
        )
        .err()
        .map(|e| e.to_string())
    };
    // Mixed sizes.
    let mut other = v.spec.clone();
    other.width = 64;
    let small = VirtualSensor::new(other).unwrap();
    let odd = dir.join("bias_odd.dng");
    write_dng(
        &small.frame(0.0, 1.0 / 8000.0, 9).unwrap(),
        &odd,
        &DngOptions::default(),
    )
    .unwrap();
    let mut b = s.bias.clone();
    b.push(odd.clone());
    let e = run(b, None).expect("mixed sizes must fail");
    assert!(e.contains("bias_odd.dng") && e.contains("size"), "{e}");
    // Mixed ISO.
    let mut f = v.frame(0.0, 1.0 / 8000.0, 10).unwrap();
    f.iso = Some(3200);
    let iso_file = dir.join("bias_iso.dng");
    write_dng(&f, &iso_file, &DngOptions::default()).unwrap();
    let mut b = s.bias.clone();
    b.push(iso_file);
    let e = run(b, None).expect("mixed ISO must fail");
    assert!(e.contains("bias_iso.dng") && e.contains("ISO 3200"), "{e}");
    // --iso that the frames do not have.
    assert!(run(s.bias.clone(), Some(800)).unwrap().contains("ISO 1600"));
    // One frame only.
    let e = run(vec![s.bias[0].clone()], None).unwrap();
    assert!(e.contains("at least 2"), "{e}");
    // An unreadable file among many.
    let junk = dir.join("bias_junk.dng");
    std::fs::write(&junk, b"II*\0garbage").unwrap();
    let mut b = s.bias.clone();
    b.insert(2, junk);
    let e = run(b, None).expect("junk must fail");
    assert!(e.contains("bias_junk.dng"), "{e}");
}

/// Frames are accumulated in file order whatever order the decoder threads
/// finish in, so two runs (here with one and with four worker threads for
/// the accumulator's parallel loops) give bit-identical maps. Before this
/// was fixed, arrival order changed the sums' rounding (~1e-14 DN) and the
/// same stacks gave files that differed from run to run.
#[test]
fn calibration_is_bit_identical_from_run_to_run() {
    let v = sensor(DarkLaw::Linear);
    let dir = scratch("repeat");
    let s = write_stacks(&v, &dir, 12);
    let input = CalibrateInput {
        bias: s.bias.clone(),
        dark: s.dark.clone(),
        flat: s.flat.clone(),
        iso: Some(1600),
        tap_pixels: 64,
        ..Default::default()
    };
    let run_with = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| calibrate(&input, &pgrf_core::NoProgress).unwrap())
    };
    let (a, b) = (run_with(1), run_with(4));
    let (ma, mb) = (a.calibration.maps.named(), b.calibration.maps.named());
    assert_eq!(ma.len(), mb.len());
    for ((name, m), (_, other)) in ma.into_iter().zip(mb) {
        let same = m
            .iter()
            .zip(other.iter())
            .all(|(x, y)| x.to_bits() == y.to_bits());
        assert!(same, "map {name} differs between runs");
    }
    assert_eq!(
        a.calibration.meta.k.to_bits(),
        b.calibration.meta.k.to_bits()
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 39: the read noise (median over pixels of the per-pixel sigma) and
/// EMVA 1288's temporal dark noise sigma_y.dark, from 8, 16 and 64 bias
/// frames of a 256 x 192 virtual sensor whose read noise spreads by 25 %
/// log-normally over its pixels: each within 1 % of the truth (the median
/// of the true sigma map; sqrt(mean sigma_r^2 + sigma_row^2 + 1/12) for
/// sigma_y.dark, which holds row noise and rounding). The median of the
/// per-pixel map itself, the estimate before, is 2-6 % low at 8 and 16.
#[test]
fn read_and_dark_noise_hold_at_8_16_and_64_frames() {
    let mut spec = SensorSpec::preset("a7s2-iso1600").unwrap();
    spec.width = 256;
    spec.height = 192;
    let v = VirtualSensor::new(spec).unwrap();
    let dir = scratch("readnoise");
    let mut cam = Shooter {
        v: &v,
        dir: dir.clone(),
        seed: 39_000,
        fits: false,
    };
    let bias = cam.shoot("bias", 64, 0.0, 1.0 / 8000.0, 0.0);
    let mut flat = cam.shoot("flat", 4, 2000.0, 0.01, 0.0);
    flat.extend(cam.shoot("flat", 4, 8000.0, 0.04, 0.0));
    let read = pgrf_core::stats::median_finite(&v.sigma_read);
    let mean_var = v
        .sigma_read
        .iter()
        .map(|&s| (s as f64).powi(2))
        .sum::<f64>()
        / v.sigma_read.len() as f64;
    let dark = (mean_var + (v.spec.row_sigma as f64).powi(2) + 1.0 / 12.0).sqrt();
    for n in [8, 16, 64] {
        let run = calibrate(
            &CalibrateInput {
                bias: bias[..n].to_vec(),
                flat: flat.clone(),
                ..Default::default()
            },
            &pgrf_core::NoProgress,
        )
        .unwrap();
        let m = &run.calibration.meta;
        let plain = pgrf_core::stats::median_finite(&run.calibration.maps.sigma_read);
        let sigma_y = m.dark_noise_sigma.unwrap();
        eprintln!(
            "{n} frames: read {:.4} (map median {plain:.4}) vs {read:.4}; sigma_y.dark {sigma_y:.4} vs {dark:.4}",
            m.read_sigma_median
        );
        let rel = |a: f64, b: f64| (a / b - 1.0).abs();
        assert!(
            rel(m.read_sigma_median, read) < 0.01,
            "{n} frames: read {} vs {read}",
            m.read_sigma_median
        );
        assert!(
            rel(sigma_y, dark) < 0.01,
            "{n} frames: sigma_y.dark {sigma_y} vs {dark}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issues 39 and 54: defective columns are found by comparing each
/// physical column with its neighbours, after the smooth shapes are taken
/// out, on the rows where they are defective. A 256 x 192 sensor
/// (monochrome, then RGGB) whose offset falls by 12 DN over its first 120
/// columns (a CCD's bias ramp), with flats that lose 30 % of their light
/// towards the corners: sensor columns 37 and 151 read 4 DN high and 3 DN
/// low in every frame (an offset, which bias subtraction removes: not
/// defects), 90 responds 8 % less and 200 6 % more to light on every row,
/// 120 responds 10 % less from row 96 down (a partial column), and the
/// edge column 255 8 % less. Exactly 90, 120, 200 and 255 are found,
/// counted once each (not per Bayer plane); 90, 200 and 255 are coded 4 on
/// every row, 120 from within 4 rows of row 96 down to the last.
#[test]
fn defective_columns_are_found_locally_despite_ramps_and_vignetting() {
    const BAD: [usize; 4] = [90, 120, 200, 255];
    for mono in [true, false] {
        let mut spec = SensorSpec::preset("a7s2-iso1600").unwrap();
        spec.width = 256;
        spec.height = 192;
        spec.mono = mono;
        spec.vignetting = 0.3;
        let v = VirtualSensor::new(spec).unwrap();
        let dir = scratch(&format!("localcolumns-{mono}"));
        let mut cam = Shooter {
            v: &v,
            dir: dir.clone(),
            seed: 39_100,
            fits: false,
        };
        let bias = cam.shoot("bias", 16, 0.0, 1.0 / 8000.0, 0.0);
        let mut flat = cam.shoot("flat", 8, 2000.0, 0.01, 0.0);
        flat.extend(cam.shoot("flat", 8, 8000.0, 0.04, 0.0));
        for f in bias.iter().chain(&flat) {
            let mut fr = pgrf_raw::decode_file(f, &Default::default()).unwrap();
            for y in 0..192 {
                for x in 0..256 {
                    let px = &mut fr.mosaic[y * 256 + x];
                    let signal = (*px as f32 - 512.0).max(0.0);
                    let mut add = if x < 120 {
                        12.0 * (1.0 - x as f32 / 120.0)
                    } else {
                        0.0
                    };
                    add += match x {
                        37 => 4.0,
                        151 => -3.0,
                        90 | 255 if signal > 200.0 => -0.08 * signal,
                        120 if signal > 200.0 && y >= 96 => -0.10 * signal,
                        200 if signal > 200.0 => 0.06 * signal,
                        _ => 0.0,
                    };
                    *px = (*px as f32 + add).round() as u16;
                }
            }
            write_dng(&fr, f, &DngOptions::default()).unwrap();
        }
        let run = calibrate(
            &CalibrateInput {
                bias,
                flat,
                ..Default::default()
            },
            &pgrf_core::NoProgress,
        )
        .unwrap();
        let m = &run.calibration.meta;
        let d = &run.calibration.maps.defects;
        // The sensor columns with a pixel coded 4 (packed plane p's column
        // j is sensor column 2 j + its column offset; the virtual sensor's
        // planes, monochrome too, are RGGB's sub-lattices).
        let mut coded: Vec<(usize, usize)> = Vec::new();
        for (p, (dy, dx)) in pgrf_raw::Cfa::Rggb.offsets().into_iter().enumerate() {
            for ((i, j), &c) in d.index_axis(ndarray::Axis(0), p).indexed_iter() {
                if c == 4.0 {
                    coded.push((2 * j + dx, 2 * i + dy));
                }
            }
        }
        let mut found: Vec<usize> = coded.iter().map(|c| c.0).collect();
        found.sort_unstable();
        found.dedup();
        let rows = |x: usize| {
            let mut r: Vec<usize> = coded.iter().filter(|c| c.0 == x).map(|c| c.1).collect();
            r.sort_unstable();
            r
        };
        eprintln!(
            "mono {mono}: {} defective columns counted, columns {found:?}",
            m.defect_columns
        );
        assert_eq!(found, BAD, "mono {mono}");
        assert_eq!(m.defect_columns, 4, "mono {mono}");
        // Every pixel of the whole bad columns is coded (none is hot,
        // dead or cold here), the partial one's from about row 96 on.
        for x in [90, 200, 255] {
            assert_eq!(
                rows(x),
                (0..192).collect::<Vec<_>>(),
                "mono {mono} column {x}"
            );
        }
        // Each row parity's stretch starts within 10 rows of row 96 (its
        // running median's reach), none above 92, every row from 106 on.
        let partial = rows(120);
        assert!(
            (92..=100).contains(&partial[0]) && partial.ends_with(&(106..192).collect::<Vec<_>>()),
            "mono {mono}: column 120 rows {partial:?}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

/// Issue 39: a monochrome sensor's calibration file holds its maps as one
/// plane (1, H, W) of its pixels, and no map holds a NaN: with a dead pixel
/// at sensor (10, 21) (its flats read the bias level), the gain map there is
/// 0 and the defect map says dead (2) at that very pixel of the plane. The
/// file reads back to the same maps; a colour sensor's stay packed.
#[test]
fn a_monochrome_calibration_file_has_single_plane_finite_maps() {
    let mut spec = SensorSpec::preset("a7s2-iso1600").unwrap();
    spec.width = 64;
    spec.height = 48;
    spec.mono = true;
    let v = VirtualSensor::new(spec).unwrap();
    let dir = scratch("monomaps");
    let s = write_stacks(&v, &dir, 8);
    let bias0 = pgrf_raw::decode_file(&s.bias[0], &Default::default()).unwrap();
    let dead = 10 * 64 + 21;
    for f in &s.flat {
        let mut fr = pgrf_raw::decode_file(f, &Default::default()).unwrap();
        fr.mosaic[dead] = bias0.mosaic[dead];
        write_dng(&fr, f, &DngOptions::default()).unwrap();
    }
    let run = calibrate(
        &CalibrateInput {
            bias: s.bias,
            dark: s.dark,
            flat: s.flat,
            ..Default::default()
        },
        &pgrf_core::NoProgress,
    )
    .unwrap();
    let c = &run.calibration;
    for (name, m) in c.maps.named() {
        assert!(
            m.iter().all(|x| x.is_finite()),
            "{name} has a non-finite value"
        );
    }
    assert_eq!(c.meta.dead_pixels, 1);
    let path = dir.join("mono.safetensors");
    c.save(&path).unwrap();
    let (_, stored) =
        pgrf_noise::mapfile::decode_maps(&std::fs::read(&path).unwrap(), &path).unwrap();
    assert_eq!(stored.len(), c.maps.named().len());
    for (name, m) in &stored {
        assert_eq!(m.shape(), [1, 48, 64], "{name}");
    }
    assert_eq!(stored["defects"][[0, 10, 21]], 2.0);
    assert_eq!(stored["gain"][[0, 10, 21]], 0.0);
    assert!(stored["gain"][[0, 10, 22]] > 0.5, "a live neighbour's gain");
    let back = Calibration::load(&path).unwrap();
    for ((name, a), (_, b)) in c.maps.named().into_iter().zip(back.maps.named()) {
        assert_eq!(a, b, "{name}");
    }
    // A colour sensor's file keeps the packed planes.
    let colour = sensor(DarkLaw::Sqrt);
    let cs = write_stacks(&colour, &dir.join("colour"), 4);
    let crun = calibrate(
        &CalibrateInput {
            bias: cs.bias,
            flat: cs.flat,
            ..Default::default()
        },
        &pgrf_core::NoProgress,
    )
    .unwrap();
    let cpath = dir.join("colour.safetensors");
    crun.calibration.save(&cpath).unwrap();
    let (_, cmaps) =
        pgrf_noise::mapfile::decode_maps(&std::fs::read(&cpath).unwrap(), &cpath).unwrap();
    assert!(cmaps.values().all(|m| m.shape() == [4, 48, 64]));
    std::fs::remove_dir_all(&dir).unwrap();
}
