//! pgrf's RAW layer: decode camera files into Bayer mosaics with their levels,
//! pack them into the 4-plane normalised arrays the rest of pgrf works on,
//! and write results back as DNG or FITS and sRGB previews.
//!
//! It reads and writes files only; frames made without a camera (procedural
//! scenes, the chart, unprocessed photos) live in pgrf-scenes.
//!
//! This crate is physics-side: plain arrays (ndarray) and rayon, no
//! deep-learning framework.

#![warn(missing_docs)]

pub mod cfa;
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
mod frame_file;
pub mod headerless;
pub mod masked;
pub mod memory;
mod orientation;
mod pack;
mod panic_guard;
mod preview;
pub mod stats;

/// Re-exported so callers use the same ndarray version as the packed arrays.
pub use ndarray;

pub use cfa::Cfa;
pub use decode::{decode_bytes, decode_file, read_temperature};
pub use demosaic::Demosaic;
pub use dng::{
    encode_dng, pixels_intact, raw_image_digest, tile_width, write_dng, Compression, DngOptions,
    DNG_TILE,
};
pub use error::{RawError, Result};
pub use fits::{FitsHeader, RowOrder};
pub use fits_frame::{encode_fits_frame, encode_fits_light, encode_fits_master, write_fits_frame};
pub use frame::{bits_for, ColorMatrix, LevelOverrides, RawFrame};
pub use frame_file::{write_frame, FrameFormat};
pub use headerless::{read_headerless, HeaderlessSpec};
pub use pack::{pack_normalized, pack_u16, unpack_normalized, unpack_u16};
pub use preview::{png_size, render_preview, Preview, PreviewOptions};
