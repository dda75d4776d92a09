//! What every network's configuration answers, so that [`super::Architecture`]
//! dispatches to the network's own file with one match arm
//! ([`super::Architecture::spec`]) instead of one per question. In a file of
//! its own so that the network files and `arch/mod.rs` share it without
//! importing each other.

use super::Extras;
use super::Method;
use crate::condition::Conditioning;
use crate::error::Result;

/// The tile cap of a network limited by memory alone: the convolutional
/// denoiser, and a flow model whose attention and statistics stay within
/// windows (its memory grows with the pixels, not their square).
pub(crate) const MEMORY_TILE_CAP: usize = 8192;
/// A network's configuration as the rest of the crate sees it: the method it
/// implements, its description, the checks before building it from a record,
/// its size and memory estimates, and what its training batches carry.
pub(crate) trait NetworkConfig {
    /// The method the network implements.
    fn method(&self) -> Method;

    /// One line for headers and errors.
    fn describe(&self) -> String;

    /// Refuse a configuration (read from a file) that pgrf cannot build,
    /// before anything is built.
    fn check(&self) -> Result<()>;

    /// A lower bound on the parameters, computed from the configuration
    /// alone (in f64: absurd records give huge values, never an overflow).
    fn min_params(&self) -> f64;

    /// Estimated peak bytes per packed pixel of one tile's forward pass
    /// (activations; attention is counted by [`NetworkConfig::attention_tokens`]).
    fn bytes_per_pixel(&self) -> f64;

    /// Tokens of the largest self-attention in an `h` x `w` tile (0 without
    /// attention).
    fn attention_tokens(&self, h: usize, w: usize) -> usize;

    /// Sides of tiles should be multiples of this (no internal padding).
    fn side_multiple(&self) -> usize;

    /// Largest tile the network should see when it runs on whole tiles,
    /// given the training patch its file records (if any). A flow model
    /// that restores within windows is limited by memory alone
    /// ([`MEMORY_TILE_CAP`]; `infer::memory::tile_cap`).
    fn tile_cap(&self, trained_patch: Option<usize>) -> usize;

    /// Whether the network is sampled from start noise X0 (a flow model)
    /// rather than run once.
    fn sampled(&self) -> bool;

    /// What a training batch carries besides (noisy, clean); `time_max` is
    /// the flow's training time range (`pgrf train --time-max`).
    fn extras(&self, time_max: f32) -> Extras;

    /// Whether the network adds a correction to its input (pgrf's
    /// residual parametrisation, not the papers').
    fn residual(&self) -> bool;

    /// How the network is told its input's noise level.
    fn conditioning(&self) -> Conditioning;

    /// Whether the network reads the capture's values below black as
    /// recorded (else clamped at 0).
    fn keeps_below_black(&self) -> bool;

    /// The parameter name of the convolution that reads the input planes.
    /// Both networks put the conditioning's planes right after the four
    /// noisy ones, so that convolution's input channels 4..4 + extra are
    /// the conditioning's (what [`super::Architecture::widen_unconditioned`]
    /// relies on).
    fn input_conv(&self) -> &'static str;
}
