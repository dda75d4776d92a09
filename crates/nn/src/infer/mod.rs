//! Full-resolution inference: input preparation, the flow's start noise,
//! tiles and their blend, and the restorer that runs either network on any
//! device.

pub mod frame;
pub mod image;
pub mod memory;
pub mod prepare;
pub mod restorer;
pub mod start;
pub mod tiles;

pub use frame::{restore_frame, restore_packed, RestoredFrame, RestoredPacked, Tiling};
pub use image::{overlap_for, restore_image, ImageOptions, DEFAULT_OVERLAP};
pub use restorer::{load, Restore, Restorer, SamplerChoice};
