//! Calibration files whose record is well-formed JSON but describes no
//! sensor: each is refused where it enters (`Calibration::from_bytes`), with
//! the field named, before synthesis or restoration divides by it or writes
//! a saturated frame from it. The base file is the `calibration` fuzz
//! target's finding (fuzz/README.md): a virtual-sensor calibration of
//! 16 x 16 pixels whose K was 1e300, which loaded and then turned the dark
//! shading `pgrf enhance --calib` subtracts into infinities.

use pgrf_calib::{CalibError, Calibration, RecordFault};
use std::path::Path;

const FOUND: &str = "tests/fuzz_regressions/k_1e300.safetensors";

fn found() -> Vec<u8> {
    std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join(FOUND)).unwrap()
}

/// The file with its pgrf record edited by `edit`: safetensors is an 8-byte
/// little-endian header length, the JSON header (the record is the string
/// `__metadata__.pgrf`), then the tensor bytes, whose offsets are relative
/// to the end of the header and so survive a header of another length.
fn with_record(bytes: &[u8], edit: impl Fn(&mut serde_json::Value)) -> Vec<u8> {
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let mut header: serde_json::Value = serde_json::from_slice(&bytes[8..8 + n]).unwrap();
    let text = header["__metadata__"]["pgrf"].as_str().unwrap();
    let mut record: serde_json::Value = serde_json::from_str(text).unwrap();
    edit(&mut record);
    header["__metadata__"]["pgrf"] = serde_json::Value::String(record.to_string());
    let h = serde_json::to_vec(&header).unwrap();
    let mut out = (h.len() as u64).to_le_bytes().to_vec();
    out.extend_from_slice(&h);
    out.extend_from_slice(&bytes[8 + n..]);
    out
}

fn load(bytes: &[u8]) -> Result<Calibration, String> {
    Calibration::from_bytes(bytes, Path::new("c.safetensors")).map_err(|e| e.to_string())
}

#[test]
fn the_fuzz_finding_is_refused_and_its_repair_loads() {
    let bytes = found();
    let e = load(&bytes).unwrap_err();
    assert!(e.contains("gain K 1e300") && !e.contains('\n'), "{e}");
    // The field at fault is there for a caller, not only in the words.
    match Calibration::from_bytes(&bytes, Path::new("c.safetensors")) {
        Err(CalibError::BadRecord {
            fault: RecordFault::Gain { k, .. },
            ..
        }) => assert_eq!(k, 1e300),
        other => panic!("expected a gain fault, got {:?}", other.err()),
    }
    // The same file with a real sensor's K loads, and its maps are finite
    // where they are used: the check refuses the record, not the file kind.
    let fixed = with_record(&bytes, |r| r["K"] = serde_json::json!(1.53));
    let c = load(&fixed).unwrap();
    let maps = c.to_pixel_maps().unwrap();
    maps.check_values().unwrap();
}

#[test]
fn records_no_sensor_could_have_are_refused_with_the_field_named() {
    let bytes = with_record(&found(), |r| r["K"] = serde_json::json!(1.53));
    use serde_json::json;
    let cases: [(&str, serde_json::Value, &str); 12] = [
        ("white", json!(0), "white level 0"),
        ("white", json!(70000), "white level 70000"),
        ("black", json!([1e9, 512, 512, 512]), "black level 1e9"),
        (
            "black",
            json!([16383, 512, 512, 512]),
            "below the white level",
        ),
        ("black", json!([-1, 512, 512, 512]), "black level -1"),
        ("K", json!(0.0), "gain K 0"),
        ("K", json!(-1.5), "gain K -1.5"),
        ("K", json!(2e4), "gain K 20000"),
        ("row_sigma", json!(1e300), "row_sigma"),
        ("width", json!(15), "frame size 15x16"),
        ("cfa", json!("RGBW"), "unknown CFA 'RGBW'"),
        ("dark_exposures_s", json!([1.0, -4.0]), "exposure -4 s"),
    ];
    for (field, value, want) in cases {
        let edited = with_record(&bytes, |r| r[field] = value.clone());
        let e = load(&edited).unwrap_err();
        assert!(
            e.contains(want) && e.contains("bad calibration record") && !e.contains('\n'),
            "{field} = {value}: {e}"
        );
    }
}

/// The `calibration` target's second finding (two inputs, one kind): a
/// well-formed record whose dark-rate map holds 5.4e37 e-/sqrt(s) at one
/// pixel. "Finite" let it through, and the dark shading for a 30 s exposure
/// (rate x sqrt(30) x K) overflowed f32 to infinity. Map values are now
/// bounded by what a sensor can have.
#[test]
fn a_map_value_no_sensor_has_is_refused() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fuzz_regressions/dark_rate_5e37.safetensors");
    let e = load(&std::fs::read(p).unwrap()).unwrap_err();
    assert!(
        e.contains("dark_rate map has an invalid value 5.3966") && e.contains("at flat index 150"),
        "{e}"
    );
    // A large but possible rate loads, and its shading stays finite.
    let bytes = with_record(&found(), |r| r["K"] = serde_json::json!(1.53));
    let c = load(&bytes).unwrap();
    assert!(c
        .dark_shading_dn(30.0)
        .unwrap()
        .iter()
        .all(|v| v.is_finite()));
}
