//! Networks for low-light RAW denoising on burn: the SID U-Net used by the
//! paper's SPC baseline and the SR3 velocity field of PGRF; training and
//! sampling to follow. The only crate that depends on the
//! deep-learning framework; everything upstream passes plain arrays.

pub mod backend;
pub mod sr3;
pub mod step;
pub mod unet;

pub use sr3::{Sr3Config, Sr3Unet};
pub use unet::{SidUnet, SidUnetConfig};
