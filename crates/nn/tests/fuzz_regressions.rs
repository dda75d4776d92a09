//! Weight files that must be refused with an error before anything large is
//! built (fuzz/README.md: the `weights` target builds networks only for
//! small records, so records like these are kept here instead).

use pgrf_nn::infer::restorer::{load_bytes, SamplerChoice};
use pgrf_nn::DeviceKind;
use std::path::{Path, PathBuf};

fn file(name: &str) -> (PathBuf, Vec<u8>) {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fuzz_regressions")
        .join(name);
    let bytes = std::fs::read(&p).unwrap();
    (p, bytes)
}

/// A 336-byte weight file whose record is a SID U-Net of width 512 and
/// which holds no tensors: a well-formed file, but the network it describes
/// has ~2e9 parameters, and loading it builds (materialises) all of them
/// before finding that no tensor fits: `pgrf enhance -m` on it allocates
/// gigabytes (2.4 GB in one allocation) before it fails. It is refused
/// from the record and the file's size alone (`Architecture::min_params`),
/// before anything is built.
#[test]
fn a_record_of_absurd_width_is_refused_before_building() {
    let (p, bytes) = file("sid_width512_no_tensors.safetensors");
    assert!(pgrf_nn::weights::from_bytes(&bytes, &p).is_ok());
    let err = load_bytes(&p, &bytes, SamplerChoice::default(), DeviceKind::Cpu)
        .err()
        .expect("refused")
        .to_string();
    assert!(
        err.contains("weights do not fit SPC denoiser (SID U-Net, width 512)")
            && err.contains("at least 1985553924 parameters")
            && err.contains("the file holds 0 values"),
        "{err}"
    );
}
