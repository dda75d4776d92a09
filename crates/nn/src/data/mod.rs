//! Training data: clean sources, augmentation and the worker-thread loader
//! that synthesises noisy/clean pairs online with pgrf-noise.

pub mod augment;
pub mod loader;
pub mod source;
pub mod validation;

pub use loader::{Batch, Extras, Loader, SampleSpec};
pub use source::{Folder, Source};
