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
//! configuration ([`TrainConfig`], [`Method`]), the networks ([`Net`]) and
//! their configurations ([`Architecture`]), the device choice ([`DeviceKind`]) and the path from a
//! dark frame to a restored one ([`infer::load`] gives a [`Restore`], which
//! [`restore_frame`] runs tile by tile as [`Tiling`] says).
//!
//! The recipe this crate owns is training from a [`TrainConfig`]
//! ([`train::run`], told how to build its pairs' noise). What pgrf does
//! with the networks (enhancing files and batches, the demo, the flow's
//! sampling search, models under evaluation) is the application's crate,
//! `pgrf-app`; this one depends on none of calibration, evaluation or
//! reports.
//!
//! # Adding a network
//!
//! One new file in [`arch`], one arm per match in `arch/mod.rs` and
//! `apply.rs`, and how the training settings make its configuration (a
//! method of [`TrainConfig`] in `config.rs`, above the networks):
//!
//! 1. `arch/NAME.rs` holds the network's configuration (a burn `Config`,
//!    serialised into weight files), its module and `forward`, and its
//!    answers to `arch::network::NetworkConfig`: the method it
//!    implements, its description, the checks before building from a record,
//!    its parameter lower bound, its memory per pixel and attention tokens,
//!    its tile multiple and cap, whether it is sampled from start noise, and
//!    what its training batches carry.
//! 2. In `arch/mod.rs`: a variant of [`Architecture`] (its record name) and
//!    of [`Net`], and that variant's arm in the matches there (its
//!    `NetworkConfig`, `init`, the parameters); in `apply.rs`, its arm in
//!    the restored batch and tile and the training loss (above `arch`,
//!    `flow` and `loss`, so that the networks depend on none of them).
//!    Nothing else in the crate matches on the networks.

#![warn(missing_docs)]

mod apply;
pub mod arch;
pub mod backend;
mod checkpoint;
pub mod condition;
mod config;
pub mod data;
mod ema;
mod error;
#[cfg(feature = "clap")]
pub mod flags;
pub mod flow;
pub mod infer;
pub mod interop;
pub mod layers;
pub mod loss;
pub mod model;
pub mod named;
pub mod norm;
pub mod ops;
pub mod schedule;
pub mod seeded;
pub mod step;
pub mod train;
pub mod weights;

pub use arch::{Architecture, Net, SidUnet, SidUnetConfig, Sr3Config, Sr3Unet};
pub use backend::DeviceKind;
pub use config::{Distance, ItemWeight, LossRule, Method, RatioDraw, TrainConfig, TrainOutputs};
pub use error::{NnError, Result};
pub use infer::{restore_frame, Restore, SamplerChoice, Tiling};
