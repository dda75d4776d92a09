//! Full-resolution inference: input preparation, the flow's start noise,
//! tiles and their blend, and the restorer that runs either network on any
//! device.
//!
//! The path `pgrf enhance` takes (the paper's Algorithm 3): [`load`] a
//! weight file as a [`Restore`] on a [`crate::DeviceKind`], then
//! [`restore_frame`] turns a decoded dark RAW into the restored frame in the
//! input's own mosaic and levels: [`prepare::network_input`] packs,
//! normalises and amplifies it, [`restore_image`] runs the network tile by
//! tile ([`tiles`], [`memory`]) with the flow's start X0 from
//! [`start::start_noise`], and the result is unpacked.

mod frame;
pub mod image;
pub mod memory;
pub mod prepare;
pub mod restorer;
pub mod start;
pub mod tiles;

pub use frame::{restore_frame, restore_packed, RestoredFrame, RestoredPacked, Tiling};
pub use image::{
    check_tiling_args, restore_image, ImageOptions, DEFAULT_OVERLAP, MIN_OVERLAP, MIN_TILE,
};
pub use restorer::{load, Restore, Restorer, SamplerChoice};
