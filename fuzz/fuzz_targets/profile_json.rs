//! Camera noise profiles (`--profile FILE.json`): serde's parse and pgrf's
//! validation in `CameraProfile::from_json`, then the per-ISO resolution a
//! validated profile goes through (`params_at_iso`).
//!
//! A crash is a panic (a validated profile that still trips an unwrap), a
//! timeout, or a profile accepted whose parameters at an ISO it accepts are
//! not finite and positive.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pgrf_noise::profile::CameraProfile;

fuzz_target!(|bytes: &[u8]| {
    let Ok(text) = std::str::from_utf8(bytes) else {
        return;
    };
    let Ok(profile) = CameraProfile::from_json("fuzz.json", text) else {
        return;
    };
    let (k_min, k_max) = profile.gain_limits();
    assert!(k_min.is_finite() && k_min > 0.0 && k_max >= k_min);
    for iso in [1, 50, 100, 400, 1600, 3200, 6400, 25_600, 409_600, u32::MAX] {
        let Ok(p) = profile.params_at_iso(iso) else {
            continue;
        };
        assert!(p.k.is_finite() && p.k > 0.0, "ISO {iso}: K {}", p.k);
        for (what, v) in [
            ("sigma_tukey", p.sigma_tukey),
            ("sigma_gauss", p.sigma_gauss),
            ("sigma_row", p.sigma_row),
        ] {
            assert!(v.is_finite() && v >= 0.0, "ISO {iso}: {what} {v}");
        }
        assert!(p.bias.iter().all(|b| b.is_finite()), "ISO {iso}: bias");
    }
});
