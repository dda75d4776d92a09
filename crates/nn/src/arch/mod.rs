//! The networks, one file each, and the one place that lists them: every
//! `match` over the networks is here and only dispatches to the network's
//! file.
//!
//! - [`sid_unet`]: the SID U-Net, the SPC denoiser (one pass);
//! - [`sr3`]: the SR3 velocity field of the PGRF flow model (sampled).
//!
//! Each network file owns its configuration (and how `pgrf train`'s
//! settings make one), its initialisation, its parameters (named by their
//! field path, [`crate::named`]), its memory estimate and what restoring a
//! tile with it needs (`network::NetworkConfig`). [`Architecture`] is the
//! configuration as a weight file records it; [`Net`] the built network.
//! Adding a network: see the crate documentation.

mod network;
pub mod sid_unet;
pub mod sr3;

pub use sid_unet::{SidUnet, SidUnetConfig};
pub use sr3::{Sr3Config, Sr3Unet};

use crate::config::{Method, TrainConfig};
use crate::data::Extras;
use crate::error::{NnError, Result};
use crate::flow::flow_loss;
use crate::flow::sample::{two_stage, Sampler};
use crate::named::{self, NamedTensor};
use crate::ops::PgrfOps;
use crate::step::denoiser_loss;
use burn::module::Module;
use burn::tensor::backend::Backend;
use burn::tensor::Tensor;
use network::NetworkConfig;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The networks and their configurations: in the weight file's record as
/// `"arch": "sid-unet" | "sr3"` with the configuration under `"config"`.
/// [`Architecture::init`] builds the network.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(tag = "arch", content = "config", rename_all = "kebab-case")]
pub enum Architecture {
    /// SPC: the SID U-Net, one pass from amplified noisy to clean.
    SidUnet(SidUnetConfig),
    /// PGRF: the SR3 velocity field of the rectified flow.
    Sr3(Sr3Config),
}

/// Either network, as one module so one optimiser type serves both. Made by
/// [`Architecture::init`] / [`Architecture::init_seeded`] or read from a
/// weight file by [`crate::model::load`]; inference wraps it in an
/// [`crate::infer::Restorer`].
// Moved rarely (once per optimiser step, by value as burn requires); boxing
// would buy nothing and complicate the derived module.
#[allow(clippy::large_enum_variant)]
#[derive(Module, Debug)]
pub enum Net<B: Backend> {
    /// The SPC denoiser: one pass from the amplified noisy input to the clean
    /// image.
    Spc(SidUnet<B>),
    /// The PGRF velocity field v(Xt, T, t), sampled by [`crate::flow::sample`].
    Pgrf(Sr3Unet<B>),
}

impl Architecture {
    /// The network's own answers ([`NetworkConfig`]): the one match every
    /// question about a configuration goes through.
    fn spec(&self) -> &dyn NetworkConfig {
        match self {
            Architecture::SidUnet(c) => c,
            Architecture::Sr3(c) => c,
        }
    }

    /// The method the weights implement: the SID U-Net is SPC, the SR3
    /// velocity field is PGRF.
    pub fn method(&self) -> Method {
        self.spec().method()
    }

    /// One line for headers and errors, e.g. "SPC denoiser (SID U-Net, width
    /// 32)" or "PGRF flow model (SR3, 64 channels x [1, 2, 4, 8, 8])".
    pub fn describe(&self) -> String {
        self.spec().describe()
    }

    /// A lower bound on the parameters of the network this describes,
    /// computed from the record alone (in f64: absurd records give huge
    /// values, never an overflow); see each network's file. A file holding
    /// fewer values cannot be this network, and is refused before anything
    /// is built: building materialises every parameter, and a 336-byte
    /// record of width 512 would otherwise cost gigabytes before failing.
    pub fn min_params(&self) -> f64 {
        self.spec().min_params()
    }

    /// Estimated peak bytes per packed pixel of one tile's forward pass
    /// ([`crate::infer::memory`]).
    pub(crate) fn bytes_per_pixel(&self) -> f64 {
        self.spec().bytes_per_pixel()
    }

    /// Tokens of the largest self-attention in an `h` x `w` tile (0 for a
    /// network without attention).
    pub fn attention_tokens(&self, h: usize, w: usize) -> usize {
        self.spec().attention_tokens(h, w)
    }

    /// Sides of tiles should be multiples of this (no internal padding).
    pub fn side_multiple(&self) -> usize {
        self.spec().side_multiple()
    }

    /// Largest tile the network should see; `trained_patch` is the training
    /// patch its file records, if any ([`crate::infer::memory`]).
    pub fn tile_cap(&self, trained_patch: Option<usize>) -> usize {
        self.spec().tile_cap(trained_patch)
    }

    /// Whether the network is sampled from start noise X0 (a flow model)
    /// rather than run once.
    pub fn sampled(&self) -> bool {
        self.spec().sampled()
    }

    /// What a training batch carries besides (noisy, clean).
    pub(crate) fn extras(&self, time_max: f32) -> Extras {
        self.spec().extras(time_max)
    }

    /// Whether the network adds a correction to its input (pgrf's residual
    /// parametrisation, not the papers').
    pub fn residual(&self) -> bool {
        self.spec().residual()
    }

    /// The tensors of a weight file under the names PyTorch code for this
    /// network knows (`pgrf export-weights`), and that naming in words.
    pub(crate) fn export_names<'a>(
        &self,
        tensors: &'a BTreeMap<String, NamedTensor>,
    ) -> Result<(Vec<(String, &'a NamedTensor)>, &'static str)> {
        match self {
            Architecture::SidUnet(_) => sid_unet::export_names(tensors),
            Architecture::Sr3(_) => sr3::export_names(tensors),
        }
    }

    /// A freshly initialised network of this architecture. Records come from
    /// files: what pgrf's 4-plane pipeline cannot run is refused before
    /// anything is built.
    pub fn init<B: Backend>(&self, device: &B::Device) -> Result<Net<B>> {
        self.spec().check()?;
        Ok(match self {
            Architecture::SidUnet(c) => Net::Spc(c.init(device)),
            Architecture::Sr3(c) => Net::Pgrf(c.init(device).map_err(NnError::Config)?),
        })
    }

    /// A network of this architecture with weights drawn from `seed`: the
    /// same seed gives the same weights whatever else the process is doing.
    pub fn init_seeded<B: Backend>(&self, device: &B::Device, seed: u64) -> Result<Net<B>> {
        crate::seeded::seeded::<B, _>(device, seed, || {
            self.init(device).map(crate::seeded::materialise)
        })
    }
}

impl TrainConfig {
    /// The network this configuration trains for `method`, checked (each
    /// network's file says how the settings make its configuration).
    pub fn architecture(&self, method: Method) -> Result<Architecture> {
        Ok(match method {
            Method::Spc => Architecture::SidUnet(SidUnetConfig::from_train_config(self)?),
            Method::Pgrf => Architecture::Sr3(Sr3Config::from_train_config(self)?),
        })
    }
}

impl<B: Backend> Net<B> {
    /// Every parameter by its field path ([`crate::named`]): what a weight
    /// file stores.
    pub(crate) fn parameters(&self) -> BTreeMap<String, NamedTensor> {
        match self {
            Net::Spc(n) => named::collect::<B, _>(n),
            Net::Pgrf(n) => named::collect::<B, _>(n),
        }
    }

    /// This network with `tensors` loaded, each by name and exact shape;
    /// the error lists the differences ([`crate::named::assign`]).
    pub(crate) fn assign(
        self,
        tensors: &BTreeMap<String, NamedTensor>,
        device: &B::Device,
    ) -> std::result::Result<Net<B>, String> {
        Ok(match self {
            Net::Spc(n) => Net::Spc(named::assign(n, tensors, device)?),
            Net::Pgrf(n) => Net::Pgrf(named::assign(n, tensors, device)?),
        })
    }

    /// Whether the network is sampled from start noise X0 (the flow model).
    pub(crate) fn sampled(&self) -> bool {
        matches!(self, Net::Pgrf(_))
    }

    /// The SPC denoiser, if this is one.
    pub fn into_denoiser(self) -> Option<SidUnet<B>> {
        match self {
            Net::Spc(n) => Some(n),
            _ => None,
        }
    }

    /// The PGRF velocity field, if this is one.
    pub fn into_flow(self) -> Option<Sr3Unet<B>> {
        match self {
            Net::Pgrf(n) => Some(n),
            _ => None,
        }
    }
}

impl<B: PgrfOps> Net<B> {
    /// The denoised batch: one pass for SPC, the two-stage sampler at `t2`
    /// for the flow model. `noisy` is T, `(n, 4, h, w)`; `x0` is X0, same
    /// shape (ignored by SPC).
    pub(crate) fn restore(&self, noisy: Tensor<B, 4>, x0: Tensor<B, 4>, t2: f32) -> Tensor<B, 4> {
        match self {
            Net::Spc(n) => n.forward(noisy),
            Net::Pgrf(n) => two_stage(n, noisy, x0, t2),
        }
    }

    /// One restored tile `(1, 4, h, w)` from the condition `cond`: the
    /// denoiser's one pass, or the mean of the flow model's `samples`
    /// samples with `sampler`, sample k starting from `x0(k)` (made one at a
    /// time, so only one start field is held).
    pub(crate) fn restore_tile(
        &self,
        cond: Tensor<B, 4>,
        samples: usize,
        x0: impl Fn(usize) -> Tensor<B, 4>,
        sampler: Sampler,
    ) -> Tensor<B, 4> {
        match self {
            Net::Spc(n) => n.forward(cond),
            Net::Pgrf(n) => {
                let mut acc: Option<Tensor<B, 4>> = None;
                for k in 0..samples {
                    let y = sampler.run(n, cond.clone(), x0(k));
                    acc = Some(match acc {
                        None => y,
                        Some(a) => a + y,
                    });
                }
                acc.expect("samples >= 1") / samples as f32
            }
        }
    }

    /// The training loss of a batch: the denoiser's L1 ([`denoiser_loss`]),
    /// or the flow's ([`flow_loss`]) with the start X0 and times t, made only
    /// when the network needs them.
    pub(crate) fn loss(
        &self,
        noisy: Tensor<B, 4>,
        clean: Tensor<B, 4>,
        x0: impl FnOnce() -> Tensor<B, 4>,
        t: impl FnOnce() -> Tensor<B, 1>,
    ) -> Tensor<B, 1> {
        match self {
            Net::Spc(n) => denoiser_loss(n, noisy, clean),
            Net::Pgrf(n) => flow_loss(n, noisy, clean, x0(), t()),
        }
    }
}
