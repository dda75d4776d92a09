//! Training data: clean sources, augmentation and the worker-thread loader
//! that synthesises noisy/clean pairs online with pgrf-noise.
//!
//! Public here: where clean images come from ([`Source`], [`Folder`]) and
//! the fixed validation pairs ([`validation::ValSet`]); the loader and the
//! augmentation serve the training loop only.

mod augment;
pub mod build;
mod cache;
mod crop;
mod loader;
pub mod photos;
pub mod source;
pub mod validation;

pub use loader::loader_rate;
pub(crate) use loader::{Batch, Loader, SampleSpec};
pub use photos::{PhotoFolder, PhotoOptions};
pub use source::{Folder, Source};
