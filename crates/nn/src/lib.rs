//! Networks for low-light RAW denoising on burn: the SID U-Net used by the
//! paper's SPC baseline and the SR3 velocity field of PGRF, their training
//! with online physics-based pair synthesis, weight files and samplers. The
//! only crate that depends on the deep-learning framework; everything
//! upstream passes plain arrays.
//!
//! Conventions shared by every module: images are packed Bayer planes
//! `(4, H/2, W/2)` in the order R, G1, B, G2 (batches `(n, 4, h, w)`),
//! normalised by each plane's black and white levels to [0, 1] and, for a
//! network input, multiplied by the exposure ratio and clamped to [0, 1].
//! The flow's symbols follow the paper: X1 the clean image, X0 ~ N(0, I) the
//! start of the path, Xt = t X1 + (1 - t) X0 the point at time t in [0, 1],
//! T the noisy condition and t2 the second time of the two-stage sampler
//! (see [`flow`]).
//!
//! The items most callers need are re-exported here: the training
//! configuration ([`TrainConfig`], [`Method`]), the two networks and their
//! configurations, the device choice ([`DeviceKind`]) and the path from a
//! dark frame to a restored one ([`infer::load`] gives a [`Restore`], which
//! [`restore_frame`] runs tile by tile as [`Tiling`] says).

#![warn(missing_docs)]

pub mod backend;
mod checkpoint;
mod config;
pub mod data;
pub mod demo;
mod error;
pub mod flow;
pub mod infer;
pub mod interop;
pub mod layers;
pub mod named;
mod net;
pub mod norm;
pub mod ops;
pub mod schedule;
pub mod seeded;
pub mod sr3;
pub mod step;
pub mod train;
mod unet;
pub mod weights;

pub use backend::DeviceKind;
pub use config::{Method, TrainConfig};
pub use error::{NnError, Result};
pub use infer::{restore_frame, Restore, SamplerChoice, Tiling};
pub use net::Net;
pub use sr3::{Sr3Config, Sr3Unet};
pub use unet::{SidUnet, SidUnetConfig};
