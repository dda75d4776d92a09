//! Per-pixel calibration files (`pgrf calibrate` output, read by `pgrf
//! synth/train/search --calib` and `pgrf enhance --calib`): safetensors
//! maps plus the JSON record, checked by `Calibration::from_bytes` (record
//! checks in `CalibMeta::check`, map shapes, map values).
//!
//! A crash is a panic, a timeout or an allocation over the limit, or a file
//! accepted with values that turn into non-finite numbers where `pgrf
//! enhance` uses it (the dark shading it subtracts).
#![no_main]

use libfuzzer_sys::fuzz_target;
use pgrf_calib::Calibration;
use std::path::Path;

fuzz_target!(|bytes: &[u8]| {
    let Ok(cal) = Calibration::from_bytes(bytes, Path::new("fuzz.safetensors")) else {
        return;
    };
    let maps = cal.to_pixel_maps().expect("checked in from_bytes");
    maps.check_values().expect("checked in from_bytes");
    // A long dark exposure, as `pgrf enhance` subtracts for a night shot.
    let shading = cal
        .dark_shading_dn(30.0)
        .expect("a non-negative exposure is accepted");
    assert!(
        shading.iter().all(|v| v.is_finite()),
        "an accepted calibration gives a non-finite dark shading"
    );
});
