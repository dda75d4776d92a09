//! Build script shared by the crates whose tests read `../shared/data` (the
//! read-only real captures and published tables beside the repository).
//! It sets `cfg(shared_data)` when the folder is there, so those tests carry
//! `#[cfg_attr(not(shared_data), ignore = "...")]` and are reported as
//! ignored, not passed, where it is absent.

fn main() {
    let manifest = std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR");
    let data = std::path::Path::new(&manifest).join("../../../shared/data");
    println!("cargo::rustc-check-cfg=cfg(shared_data)");
    println!("cargo::rerun-if-changed={}", data.display());
    if data.is_dir() {
        println!("cargo::rustc-cfg=shared_data");
    }
}
