//! Issue 39: every FITS file pgrf writes, read back header by header.
//!
//! pgrf writes FITS in two ways: frames (`pgrf convert`, `pgrf
//! simulate-sensor`: `pgrf_raw::write_frame`) and calibration masters
//! (`pgrf calibrate --masters`: `calibrate_to_files`). Each must keep the
//! rows in the order its input stored them and say which in ROWORDER (an
//! input without ROWORDER is BOTTOM-UP by the FITS convention, never
//! written as TOP-DOWN), and carry SATURATE only on integer ADU samples,
//! never on a master's samples normalised to 0-1.
//!
//! With PGRF_FITS_HEADERS_DIR set, the files are also copied there for
//! tests/reference/fits_headers_astropy.py, which checks the same with
//! astropy.

use pgrf_calib::{calibrate_to_files, CalibrateConfig, CalibrateInput, CalibrationRun, RunHooks};
use pgrf_noise::sensor::{SensorSpec, VirtualSensor};
use pgrf_raw::fits::{encode_fits_u16, FitsCard, FitsValue};
use pgrf_raw::{decode_file, write_frame, Cfa, DngOptions, RowOrder};
use std::path::{Path, PathBuf};

fn scratch(name: &str) -> PathBuf {
    let d =
        std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("pgrf-fits-headers-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The header cards of a FITS file, key and value (quotes and padding of
/// strings removed, comment dropped), up to END.
fn header(path: &Path) -> Vec<(String, String)> {
    let bytes = std::fs::read(path).unwrap();
    bytes
        .chunks(80)
        .map(|c| String::from_utf8_lossy(c).to_string())
        .take_while(|c| !c.starts_with("END "))
        .filter(|c| c.get(8..10) == Some("= "))
        .map(|c| {
            let v = c[10..].trim();
            let v = match v.strip_prefix('\'') {
                Some(rest) => rest.split('\'').next().unwrap_or("").trim_end().to_string(),
                None => v.split('/').next().unwrap_or("").trim().to_string(),
            };
            (c[..8].trim().to_string(), v)
        })
        .collect()
}

fn value(h: &[(String, String)], key: &str) -> Option<String> {
    h.iter().find(|(k, _)| k == key).map(|(_, v)| v.clone())
}

/// No report is drawn here.
struct NoReport;

impl RunHooks for NoReport {
    type Error = pgrf_calib::CalibError;
    fn write_report(&self, _: &Path, _: &CalibrationRun) -> Result<usize, Self::Error> {
        Ok(0)
    }
}

/// How many DN each stored row adds to every frame: a ramp that shows
/// which way up a master came out.
const RAMP: u16 = 4;

/// One input stack's files: a virtual sensor's frames (64 x 48) with the
/// ramp added by stored row, written with `roworder` (None: no keyword) and
/// for a colour sensor BAYERPAT = RGGB.
fn write_case(dir: &Path, roworder: Option<&str>, colour: bool) -> CalibrateInput {
    let mut spec = SensorSpec::preset("a7s2-iso1600").unwrap();
    spec.width = 64;
    spec.height = 48;
    spec.mono = !colour;
    let v = VirtualSensor::new(spec).unwrap();
    let mut seed = 500;
    let mut shoot = |sub: &str, n: usize, e: f32, t: f32| -> Vec<PathBuf> {
        let d = dir.join(sub);
        std::fs::create_dir_all(&d).unwrap();
        (0..n)
            .map(|i| {
                seed += 1;
                let f = v.frame(e, t, seed).unwrap();
                let data: Vec<u16> = f
                    .mosaic
                    .iter()
                    .enumerate()
                    .map(|(k, &x)| x + RAMP * (k / f.width) as u16)
                    .collect();
                let mut cards = vec![FitsCard::new("EXPTIME", FitsValue::Float(t as f64), "")];
                if let Some(r) = roworder {
                    cards.push(FitsCard::new("ROWORDER", FitsValue::Str(r.into()), ""));
                }
                if colour {
                    cards.push(FitsCard::new("BAYERPAT", FitsValue::Str("RGGB".into()), ""));
                }
                let p = d.join(format!("{sub}_{t}_{i}.fits"));
                let bytes = encode_fits_u16(f.width, f.height, &data, &cards).unwrap();
                std::fs::write(&p, bytes).unwrap();
                p
            })
            .collect()
    };
    let bias = shoot("bias", 4, 0.0, 0.001);
    let mut dark = shoot("dark", 1, 0.0, 10.0);
    dark.extend(shoot("dark", 1, 0.0, 20.0));
    let mut flat = shoot("flat", 2, 2000.0, 1.0);
    flat.extend(shoot("flat", 2, 6000.0, 3.0));
    CalibrateInput {
        bias,
        dark,
        flat,
        ..Default::default()
    }
}

/// The mean of each stored row of a decoded frame, DN.
fn row_means(path: &Path) -> Vec<f64> {
    let f = decode_file(path, &Default::default()).unwrap();
    f.mosaic
        .chunks(f.width)
        .map(|r| r.iter().map(|&x| x as f64).sum::<f64>() / r.len() as f64)
        .collect()
}

/// Masters from stacks stored every way: no ROWORDER (BOTTOM-UP by
/// convention), BOTTOM-UP, TOP-DOWN, and a BOTTOM-UP colour sensor. Each
/// of the 5 masters per case states the input's order, has no SATURATE
/// (BITPIX -32, samples at most 1), and holds the ramp the right way up:
/// its last stored row's mean lies 47 x 4 = 188 DN above its first (the
/// bias's within 5 DN; flats and darks within 5 % of their level). A frame
/// written from a decoded input (`pgrf convert`) keeps the order and states
/// SATURATE 65535; a virtual-sensor frame (`pgrf simulate-sensor`) is
/// TOP-DOWN. A colour master reads back with the input's stored phase.
#[test]
fn every_fits_output_states_its_row_order_and_no_saturate_on_0_1_data() {
    let out = std::env::var_os("PGRF_FITS_HEADERS_DIR").map(PathBuf::from);
    let root = scratch("cases");
    for (case, roworder, colour, want) in [
        ("none", None, false, "BOTTOM-UP"),
        ("bottom-up", Some("BOTTOM-UP"), false, "BOTTOM-UP"),
        ("top-down", Some("TOP-DOWN"), false, "TOP-DOWN"),
        ("colour-bottom-up", Some("BOTTOM-UP"), true, "BOTTOM-UP"),
    ] {
        let dir = root.join(case);
        let input = write_case(&dir, roworder, colour);
        let first_bias = input.bias[0].clone();
        let config = CalibrateConfig {
            input,
            output: dir.join("calib.safetensors"),
            masters: Some(dir.join("masters")),
            ..Default::default()
        };
        let outcome = calibrate_to_files(&config, &pgrf_core::NoProgress, &NoReport)
            .unwrap_or_else(|e| panic!("{case}: {e}"));
        assert_eq!(outcome.masters, Some(5), "{case}");
        let mut masters: Vec<PathBuf> = std::fs::read_dir(dir.join("masters"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "fits"))
            .collect();
        masters.sort();
        assert_eq!(masters.len(), 5, "{case}: {masters:?}");
        let input_frame = decode_file(&first_bias, &Default::default()).unwrap();
        for m in &masters {
            let h = header(m);
            let name = m.file_name().unwrap().to_string_lossy().to_string();
            assert_eq!(
                value(&h, "ROWORDER").as_deref(),
                Some(want),
                "{case} {name}"
            );
            assert_eq!(value(&h, "SATURATE"), None, "{case} {name}");
            assert_eq!(value(&h, "BITPIX").as_deref(), Some("-32"), "{case} {name}");
            let rows = row_means(m);
            let (first, last) = (rows[0], rows[rows.len() - 1]);
            let rise = last - first;
            let want_rise = (RAMP as f64) * 47.0;
            let slack = if name.starts_with("master_bias") {
                5.0
            } else {
                5.0_f64.max(0.05 * first)
            };
            assert!(
                (rise - want_rise).abs() < slack,
                "{case} {name}: rows rise {rise} DN, want {want_rise}"
            );
            let back = decode_file(m, &Default::default()).unwrap();
            assert_eq!(back.mono, !colour, "{case} {name}");
            assert_eq!(back.row_order(), input_frame.row_order(), "{case} {name}");
            if colour {
                assert_eq!(back.cfa, input_frame.cfa, "{case} {name}");
            }
        }
        // A frame written from a decoded input, as `pgrf convert` does.
        let converted = dir.join("converted.fits");
        write_frame(&input_frame, &converted, &DngOptions::default()).unwrap();
        let h = header(&converted);
        assert_eq!(value(&h, "ROWORDER").as_deref(), Some(want), "{case}");
        assert_eq!(value(&h, "SATURATE").as_deref(), Some("65535"), "{case}");
        assert_eq!(row_means(&converted), row_means(&first_bias), "{case}");
        if colour {
            // Stored RGGB BOTTOM-UP of height 48 is GBRG at stored row 0;
            // BAYERPAT states it seen top-down: RGGB again.
            assert_eq!(input_frame.cfa, Cfa::Gbrg);
            assert_eq!(value(&h, "BAYERPAT").as_deref(), Some("RGGB"));
        }
        if let Some(o) = &out {
            let d = o.join(case);
            std::fs::create_dir_all(&d).unwrap();
            std::fs::copy(&first_bias, d.join("input_bias.fits")).unwrap();
            std::fs::copy(&converted, d.join("converted.fits")).unwrap();
            for m in &masters {
                std::fs::copy(m, d.join(m.file_name().unwrap())).unwrap();
            }
        }
    }
    // A virtual sensor's frame as `pgrf simulate-sensor --format fits`
    // writes it: top row first.
    let mut spec = SensorSpec::preset("a7s2-iso1600").unwrap();
    spec.width = 16;
    spec.height = 8;
    let f = VirtualSensor::new(spec)
        .unwrap()
        .frame(0.0, 1.0, 1)
        .unwrap();
    assert_eq!(f.row_order(), RowOrder::TopDown);
    let sim = root.join("simulated.fits");
    write_frame(&f, &sim, &DngOptions::default()).unwrap();
    let h = header(&sim);
    assert_eq!(value(&h, "ROWORDER").as_deref(), Some("TOP-DOWN"));
    assert_eq!(value(&h, "SATURATE").as_deref(), Some("16383"));
    if let Some(o) = &out {
        std::fs::copy(&sim, o.join("simulated.fits")).unwrap();
    }
    std::fs::remove_dir_all(&root).unwrap();
}

/// A TOP-DOWN frame among bias frames without ROWORDER (BOTTOM-UP) would
/// be averaged upside down: the run stops naming it.
#[test]
fn a_stack_of_mixed_row_orders_is_refused() {
    let dir = scratch("mixed");
    let mut input = write_case(&dir.join("a"), None, false);
    let other = write_case(&dir.join("b"), Some("TOP-DOWN"), false);
    input.bias.push(other.bias[0].clone());
    let e = pgrf_calib::calibrate(&input, &pgrf_core::NoProgress)
        .err()
        .expect("mixed row orders must be refused")
        .to_string();
    assert!(
        e.contains("b/bias/") && e.contains("row order TOP-DOWN") && e.contains("BOTTOM-UP"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A binned frame (XBINNING = 2) among unbinned bias frames would be
/// averaged with pixels of another size: the run stops naming it.
#[test]
fn a_stack_of_mixed_binnings_is_refused() {
    let dir = scratch("binned");
    let mut input = write_case(&dir.join("a"), None, false);
    let first = &input.bias[0];
    let img = pgrf_raw::fits::read_fits(first, &std::fs::read(first).unwrap()).unwrap();
    let cards = [
        FitsCard::new("EXPTIME", FitsValue::Float(0.001), ""),
        FitsCard::new("XBINNING", FitsValue::Int(2), ""),
    ];
    let binned = dir.join("binned.fits");
    std::fs::write(
        &binned,
        encode_fits_u16(img.width, img.height, &img.data, &cards).unwrap(),
    )
    .unwrap();
    input.bias.push(binned);
    let e = pgrf_calib::calibrate(&input, &pgrf_core::NoProgress)
        .err()
        .expect("mixed binnings must be refused")
        .to_string();
    assert!(
        e.contains("binned.fits") && e.contains("binning 2x1") && e.contains("none stated"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The calibration keeps its frames' row order in its record, and refuses
/// a light frame stored the other way up (its maps would lie mirrored on
/// it), while one stored alike passes.
#[test]
fn a_calibration_refuses_a_frame_stored_the_other_way_up() {
    let dir = scratch("apply");
    let input = write_case(&dir.join("a"), None, false);
    let other = write_case(&dir.join("b"), Some("TOP-DOWN"), false);
    let config = CalibrateConfig {
        input: input.clone(),
        output: dir.join("calib.safetensors"),
        ..Default::default()
    };
    calibrate_to_files(&config, &pgrf_core::NoProgress, &NoReport).unwrap();
    let cal = pgrf_calib::Calibration::load(&dir.join("calib.safetensors")).unwrap();
    assert_eq!(cal.meta.row_order, Some(RowOrder::BottomUp));
    let alike = decode_file(&input.flat[0], &Default::default()).unwrap();
    assert!(cal.check_layout(&alike).is_ok());
    let flipped = decode_file(&other.flat[0], &Default::default()).unwrap();
    let e = cal.check_layout(&flipped).unwrap_err().to_string();
    assert!(
        e.contains("rows BOTTOM-UP") && e.contains("frame's are TOP-DOWN"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
