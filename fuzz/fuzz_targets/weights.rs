//! Weight files (`pgrf enhance/search/eval --model FILE`): safetensors
//! tensors plus the JSON record, read by `pgrf_nn::weights::from_bytes`
//! (record format and version, tensors f32 and finite), then the checks
//! made before a network is built from the record (`Architecture::init`:
//! SID U-Net width and planes, SR3 levels, groups, channels, dropout) and
//! the loading of the tensors into it by name and shape, as
//! `pgrf_nn::infer::restorer::load_bytes` does for `pgrf enhance`.
//!
//! Building the network materialises every parameter the record describes,
//! so it is done only for records whose parameter count (an upper bound
//! computed here from the record, without building anything) is below
//! `BUILD_LIMIT`: each exec stays cheap, and a record of absurd widths is
//! not turned into gigabytes of weights per exec by this harness. What
//! pgrf itself does with such a record is the business of the record
//! checks (see README.md).
//!
//! A crash is a panic, a timeout, an allocation over the limit, or a file
//! accepted whose network does not hold exactly the file's tensors.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pgrf_nn::infer::restorer::{load_bytes, SamplerChoice};
use pgrf_nn::weights;
use pgrf_nn::Architecture;
use pgrf_nn::DeviceKind;
use std::path::Path;

/// Records describing more parameters than this (an upper bound, see
/// `param_bound`) are not built. pgrf itself refuses, before building, any
/// record whose network needs more values than the file holds
/// (`Architecture::min_params`), so files of at most `-max_len` bytes
/// reach the build only with small SID U-Nets; SR3 records of many tiny
/// levels are cheap in values but not in modules, hence both limits.
const BUILD_LIMIT: f64 = 1e6;
/// Nor are records with more residual blocks than this (SR3 blocks with
/// few channels are cheap in parameters but not in modules).
const BLOCK_LIMIT: f64 = 1e4;

/// An upper bound on the parameters of the network `arch` describes and
/// the number of its residual blocks, in f64 (no overflow; absurd records
/// give huge or infinite values).
fn param_bound(arch: &Architecture) -> (f64, f64) {
    let conv = |k: f64, a: f64, b: f64| k * k * a * b + b;
    match arch {
        // Exact for the SID U-Net (pgrf's own hand count).
        Architecture::SidUnet(_) => (arch.min_params(), 0.0),
        Architecture::Sr3(c) => {
            let inner = c.inner_channels as f64;
            let levels = c.channel_mults.len() as f64;
            let widest = inner * c.channel_mults.iter().copied().max().unwrap_or(0) as f64;
            let blocks = levels * (2.0 * c.res_blocks as f64 + 1.0) + 2.0;
            // A residual block from at most 2C to at most C channels with
            // attention: norms, two 3x3 convs, the time projection, the 1x1
            // skip, the attention's norm and 1x1 projections (~33 C^2).
            let block = 40.0 * widest * widest + inner * widest + 20.0 * widest + 100.0;
            let total = conv(3.0, c.in_channels as f64, inner)
                + 8.0 * inner * inner
                + 5.0 * inner
                + blocks * block
                + 2.0 * levels * conv(3.0, widest, widest)
                + 2.0 * widest
                + conv(3.0, widest, c.out_channels as f64);
            (total, blocks)
        }
    }
}

fuzz_target!(|bytes: &[u8]| {
    let path = Path::new("fuzz.safetensors");
    let Ok((meta, tensors)) = weights::from_bytes(bytes, path) else {
        return;
    };
    let mut elements = 0u64;
    for (name, t) in &tensors {
        let n = t
            .shape
            .iter()
            .try_fold(1u64, |a, &d| a.checked_mul(d as u64))
            .expect("shape product fits");
        assert_eq!(n, t.values.len() as u64, "tensor {name}");
        assert!(t.values.iter().all(|v| v.is_finite()), "tensor {name}");
        elements += n;
    }
    let _ = meta.arch.describe();
    let (params, blocks) = param_bound(&meta.arch);
    if !(params <= BUILD_LIMIT && blocks <= BLOCK_LIMIT) {
        return;
    }
    let Ok(restorer) = load_bytes(path, bytes, SamplerChoice::default(), DeviceKind::Cpu) else {
        return;
    };
    // Loaded: every parameter came from the file and no tensor was left over.
    assert_eq!(restorer.weight_bytes(), 4 * elements);
    assert!(restorer.side_multiple() >= 1);
});
