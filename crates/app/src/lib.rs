//! What pgrf does with its networks, one recipe per command, over the
//! networks, training and tensor inference of `pgrf-nn`:
//!
//! - [`array`](mod@array): a packed array restored as `pgrf enhance` restores a
//!   file's (the Python package's `Model.restore`);
//! - [`builtin`]: the models built in (`builtin:spc`, `builtin:pgrf`) and
//!   loading a model by name or file;
//! - [`enhance`]: a dark RAW file, or a batch of them, restored to a DNG
//!   (calibration, exposure ratio, noise lookup, masked black, tiles),
//!   with the batch runner's shards, manifests and skip-existing;
//! - [`demo`]: the built-in photograph made dark and restored by the
//!   built-in models, scored and pictured;
//! - [`search`]: the flow model's sampling search (the paper's Algorithm 2)
//!   on validation pairs, its plot and the t2 written into the weight file;
//! - [`method`]: a network as a method under `pgrf eval`;
//! - [`train`]: `pgrf train`'s recipe, which builds the pairs' noise from
//!   profiles and a calibration for `pgrf_nn::train`.
//!
//! This crate, not `pgrf-nn`, depends on calibration, evaluation and
//! reports, so the networks can be used without the whole product.

#![warn(missing_docs)]

pub mod array;
pub mod builtin;
pub mod demo;
pub mod enhance;
pub mod method;
pub mod search;
pub mod train;
