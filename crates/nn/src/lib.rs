//! Networks for low-light RAW denoising on burn: the SID U-Net used by the
//! paper's SPC baseline (and, later, the SR3 velocity field of PGRF), with
//! training and sampling to follow. The only crate that depends on the
//! deep-learning framework; everything upstream passes plain arrays.

pub mod unet;

pub use unet::{SidUnet, SidUnetConfig};
