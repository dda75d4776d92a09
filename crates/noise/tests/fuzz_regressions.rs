//! Camera profiles the `profile_json` fuzz target found (fuzz/README.md):
//! each must be refused by `CameraProfile::from_json` with one line naming
//! the field, never accepted and turned into infinite noise later.

use pgrf_noise::profile::CameraProfile;
use std::path::Path;

#[test]
fn a_k_per_iso_of_1e300_is_refused() {
    // The built-in D850 profile with k_per_iso 1e300: validated as "a
    // positive number", then K = 1e300 x ISO was infinite at ISO 1600.
    let p =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz_regressions/k_per_iso_1e300.json");
    let text = std::fs::read_to_string(p).unwrap();
    let e = CameraProfile::from_json("k_per_iso_1e300.json", &text)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("k_per_iso 1e300") && e.contains("beyond any sensor") && !e.contains('\n'),
        "{e}"
    );
    // The file is otherwise the built-in profile: with the published
    // relation back it loads (the refusal is the value's, not the file's).
    let fixed = text
        .replace("1e+300", "0.0009563")
        .replace("1e300", "0.0009563");
    assert!(CameraProfile::from_json("fixed.json", &fixed).is_ok());
}
