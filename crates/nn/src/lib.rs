//! Networks for low-light RAW denoising on burn: the SID U-Net used by the
//! paper's SPC baseline and the SR3 velocity field of PGRF, their training
//! with online physics-based pair synthesis, weight files and samplers. The
//! only crate that depends on the deep-learning framework; everything
//! upstream passes plain arrays.

pub mod backend;
pub mod checkpoint;
pub mod config;
pub mod data;
pub mod error;
pub mod flow;
pub mod infer;
pub mod layers;
pub mod named;
pub mod net;
pub mod norm;
pub mod schedule;
pub mod seeded;
pub mod sr3;
pub mod step;
pub mod train;
pub mod unet;
pub mod weights;

pub use config::{Method, TrainConfig};
pub use error::{NnError, Result};
/// The samplers under their former path (`pgrf_nn::sample::SamplerKind`);
/// they live in [`flow::sample`].
pub use flow::sample;
pub use sr3::{Sr3Config, Sr3Unet};
pub use unet::{SidUnet, SidUnetConfig};
