//! pgrf's training and demo material: clean RAW frames that no camera
//! recorded. Procedural scenes (dead leaves, gradients) rendered from a
//! seed, the colour test chart, the demo's scene, and ordinary photos
//! (JPEG, PNG, TIFF) decoded and unprocessed into a camera's RAW space.
//!
//! It sits on top of pgrf-raw, which reads and writes files only: the
//! frames made here are [`pgrf_raw::RawFrame`]s with levels and colour
//! metadata, so everything downstream treats them like a camera's.
//!
//! This crate is physics-side: plain arrays (ndarray) and rayon, no
//! deep-learning framework.

#![warn(missing_docs)]

pub mod chart;
pub mod demo;
mod error;
pub mod photo;
pub mod scene;
pub mod unprocess;

pub use error::{Result, SceneError};
pub use scene::{render_frame, render_packed, SceneKind, SceneLevels, SceneSpec};
