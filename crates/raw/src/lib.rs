//! pgrf's RAW layer: decode camera files into Bayer mosaics with their levels,
//! pack them into the 4-plane normalised arrays the rest of pgrf works on,
//! and write results back as DNG and sRGB previews.
//!
//! This crate is physics-side: plain arrays (ndarray) and rayon, no
//! deep-learning framework.

#![warn(missing_docs)]

pub mod cfa;
pub mod chart;
pub mod color;
pub mod container;
mod decode;
mod demosaic;
mod dng;
mod error;
pub mod files;
pub mod fits;
mod fits_frame;
mod frame;
pub mod headerless;
mod orientation;
mod pack;
mod panic_guard;
pub mod photo;
mod preview;
pub mod scene;
pub mod stats;
pub mod unprocess;

/// Re-exported so callers use the same ndarray version as the packed arrays.
pub use ndarray;

pub use cfa::Cfa;
pub use decode::{decode_bytes, decode_file};
pub use demosaic::Demosaic;
pub use dng::{encode_dng, write_dng, Compression, DngOptions};
pub use error::{RawError, Result};
pub use fits_frame::{encode_fits_frame, encode_fits_master, write_fits_frame, FitsHeader};
pub use frame::{ColorMatrix, LevelOverrides, RawFrame};
pub use headerless::{read_headerless, HeaderlessSpec};
pub use pack::{pack_normalized, pack_u16, unpack_normalized, unpack_u16};
pub use preview::{render_preview, Preview, PreviewOptions};
pub use scene::{render_frame, render_packed, SceneKind, SceneLevels, SceneSpec};
