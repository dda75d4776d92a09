//! Headerless sensor dumps: bare little-endian u16 samples, row by row, as
//! written by sensor evaluation boards and ISP test benches. Nothing in the
//! file says how to read it, so the user states geometry, CFA and levels.

use crate::cfa::Cfa;
use crate::error::{RawError, Result};
use crate::frame::{black_per_plane, RawFrame};
use std::path::Path;

/// How to interpret a headerless dump.
#[derive(Clone, Debug)]
pub struct HeaderlessSpec {
    /// Width of the dump in pixels.
    pub width: usize,
    /// Height of the dump in pixels.
    pub height: usize,
    /// Significant bits per sample (samples above 2^bits - 1 are refused).
    pub bits: u32,
    /// Bayer phase of the first sample; None for a monochrome sensor.
    pub cfa: Option<Cfa>,
    /// One black level for all planes, or R, G1, B, G2.
    pub black: Vec<f32>,
    /// Saturation level in DN; defaults to 2^bits - 1.
    pub white: Option<u32>,
    /// Samples are big-endian u16 (the default, false, is little-endian).
    pub big_endian: bool,
}

/// Read a headerless dump. The file must hold exactly `width * height` u16
/// samples: a shorter file is truncated, a longer one is the wrong geometry.
/// Up to 1% of samples may exceed the bit depth (defective pixels); use
/// [`samples_above_range`] to report them.
pub fn read_headerless(path: &Path, spec: &HeaderlessSpec) -> Result<RawFrame> {
    if path.is_dir() {
        return Err(RawError::unsupported(
            path,
            "is a directory, expected a raw dump",
        ));
    }
    if !(1..=16).contains(&spec.bits) {
        return Err(RawError::BadBits { bits: spec.bits });
    }
    let bytes = std::fs::read(path).map_err(|e| RawError::io(path, e))?;
    let want = spec
        .width
        .checked_mul(spec.height)
        .and_then(|n| n.checked_mul(2))
        .ok_or(RawError::SizeOverflow {
            width: spec.width,
            height: spec.height,
        })?;
    if bytes.len() != want {
        return Err(RawError::decode(
            path,
            format!(
                "file has {} bytes, a {}x{} 16-bit dump needs {want} ({})",
                bytes.len(),
                spec.width,
                spec.height,
                if bytes.len() < want {
                    "truncated?"
                } else {
                    "wrong size given?"
                }
            ),
        ));
    }
    let max = ((1u32 << spec.bits) - 1) as u16;
    let mosaic: Vec<u16> = bytes
        .chunks_exact(2)
        .map(|b| {
            if spec.big_endian {
                u16::from_be_bytes([b[0], b[1]])
            } else {
                u16::from_le_bytes([b[0], b[1]])
            }
        })
        .collect();
    // A few samples above the declared range are sensor defects (stuck pixels
    // read as 0xFFFF) and are kept as they are; many of them mean the bit depth
    // or byte order is wrong, and decoding on would give garbage.
    let above = mosaic.iter().filter(|&&v| v > max).count();
    if above * 100 > mosaic.len() {
        return Err(RawError::decode(
            path,
            format!(
                "{above} of {} samples exceed the {}-bit range (wrong bit depth or byte order?)",
                mosaic.len(),
                spec.bits
            ),
        ));
    }
    let black = black_per_plane(&spec.black)?;
    let white = spec.white.unwrap_or(max as u32);
    let mut frame = RawFrame::from_mosaic(
        spec.width,
        spec.height,
        mosaic,
        spec.cfa.unwrap_or(Cfa::Rggb),
        black,
        white,
    )?;
    frame.mono = spec.cfa.is_none();
    frame.bits = spec.bits;
    Ok(frame)
}

/// How many samples exceed the frame's declared bit depth.
pub fn samples_above_range(frame: &RawFrame) -> usize {
    let max = if frame.bits >= 16 {
        u16::MAX
    } else {
        ((1u32 << frame.bits) - 1) as u16
    };
    frame.mosaic.iter().filter(|&&v| v > max).count()
}
