//! RAW decode + pack: the path `pgrf` takes on a camera file. The container
//! check, rawler's decode (its panics are turned into errors by pgrf's
//! panic guard, which is part of what is tested), the frame's levels and
//! the 4-plane normalised packing every later step works on.
//!
//! A crash here is a panic that escaped pgrf, an abort, a timeout, an
//! allocation over the limit, or a frame that decoded `Ok` but is
//! inconsistent (the assertions below).
#![no_main]

use libfuzzer_sys::fuzz_target;
use pgrf_raw::{decode_bytes, pack_normalized, LevelOverrides};
use std::path::Path;

fuzz_target!(|bytes: &[u8]| {
    // What `decode_bytes` runs first; called on its own as well so a
    // panic in the walk itself is told apart from one in the decoder.
    let checked = pgrf_raw::container::check(bytes);
    let decoded = decode_bytes(Path::new("fuzz.raw"), bytes, &LevelOverrides::default());
    let Ok(frame) = decoded else {
        return;
    };
    assert!(
        checked.is_ok(),
        "decode accepted a container the check refused"
    );
    assert_eq!(frame.mosaic.len(), frame.width * frame.height);
    assert!(frame.width >= 2 && frame.height >= 2);
    assert!(frame.white >= 1 && frame.white <= u32::from(u16::MAX));
    for b in frame.black {
        assert!(b.is_finite() && b >= 0.0 && b < frame.white as f32);
    }
    let packed = pack_normalized(&frame, false).expect("a decoded frame packs");
    assert_eq!(
        packed.shape(),
        [4, frame.height / 2, frame.width / 2],
        "packed shape"
    );
    assert!(
        packed.iter().all(|v| v.is_finite()),
        "non-finite value after normalisation"
    );
});
