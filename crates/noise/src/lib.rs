//! Physics noise models for low-light RAW: Poisson-Gaussian (Foi), ELD's
//! Tukey-lambda + row + quantisation model, and the PGRF composite with
//! per-pixel maps and a dark-current x fixed-pattern term; camera profiles
//! built from published calibrations; exact, thread-count-independent sampling.
//!
//! Physics-side crate: ndarray and rayon only, no deep-learning framework.
//! Images are packed `(4, H/2, W/2)` normalised arrays as produced by
//! `pgrf_raw::pack_normalized`.

#![warn(missing_docs)]

pub mod bank;
pub mod capture;
pub mod catalog;
mod components;
pub mod darktable;
pub mod describe;
mod error;
pub mod estimate;
mod fast;
pub mod lookup;
pub mod mapfile;
mod maps;
pub mod mix;
mod model;
pub mod pair;
mod params;
pub mod pg_profile;
mod poisson;
pub mod profile;
pub mod sensor;
pub mod sensor_stacks;
mod tukey;

pub use components::Components;
pub use error::{NoiseError, ProfileFault, Result};
pub use maps::{Map, PixelMaps};
pub use model::{Capture, ModelKind, NoiseModel, ReadDist};
pub use params::CaptureParams;
pub use profile::{CameraProfile, DarkLaw};
