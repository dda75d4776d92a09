//! The networks, one file each, and the one place that lists them: every
//! `match` over the networks is here (and, for restoring and the training
//! loss, in `crate::apply`, above the flow and the losses) and only
//! dispatches to the network's file.
//!
//! - [`sid_unet`]: the SID U-Net, the SPC denoiser (one pass);
//! - [`sr3`]: the SR3 velocity field of the PGRF flow model (sampled).
//!
//! Each network file owns its configuration, its initialisation, its
//! parameters (named by their
//! field path, [`crate::named`]), its memory estimate and what restoring a
//! tile with it needs (`network::NetworkConfig`). [`Architecture`] is the
//! configuration as a weight file records it; [`Net`] the built network.
//! Adding a network: see the crate documentation.

mod kinds;
mod network;
mod prior;
pub mod sid_names;
pub mod sid_unet;
pub mod sr3;
mod widen;

pub use kinds::{Extras, Method};
pub(crate) use network::MEMORY_TILE_CAP;
pub(crate) use prior::is_prior;
pub use prior::PriorFlowConfig;
pub use sid_unet::{SidUnet, SidUnetConfig};
pub use sr3::{Sr3Config, Sr3Unet};

use crate::condition::Conditioning;
use crate::error::{ArchFault, Result};
use crate::named::{self, Mismatch, NamedTensor};
use crate::ops::PgrfOps;
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
    /// PGRF started from an SPC denoiser's restoration ([`PriorFlowConfig`]).
    Sr3Prior(PriorFlowConfig),
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
            Architecture::Sr3Prior(c) => c,
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

    /// How the network is told its input's noise level
    /// ([`crate::condition`]).
    pub fn conditioning(&self) -> Conditioning {
        self.spec().conditioning()
    }

    /// Whether the network reads the capture's values below black as
    /// recorded; else its input is clamped at 0 (SID's convention).
    pub fn keeps_below_black(&self) -> bool {
        self.spec().keeps_below_black()
    }

    /// The tensors of a weight file under the names PyTorch code for this
    /// network knows (`pgrf export-weights`), and that naming in words.
    pub(crate) fn export_names<'a>(
        &self,
        tensors: &'a BTreeMap<String, NamedTensor>,
    ) -> Result<(Vec<(String, &'a NamedTensor)>, &'static str)> {
        match self {
            Architecture::SidUnet(_) => sid_unet::export_names(tensors),
            Architecture::Sr3(_) | Architecture::Sr3Prior(_) => sr3::export_names(tensors),
        }
    }

    /// This architecture without its conditioning: the network that reads
    /// only the noisy planes (and, for the flow, Xt).
    pub fn unconditioned(&self) -> Architecture {
        let extra = self.conditioning().extra_channels();
        match self {
            Architecture::SidUnet(c) => Architecture::SidUnet(
                c.clone()
                    .with_conditioning(Conditioning::None)
                    .with_in_channels(c.in_channels.saturating_sub(extra)),
            ),
            Architecture::Sr3(c) => Architecture::Sr3(
                c.clone()
                    .with_conditioning(Conditioning::None)
                    .with_in_channels(c.in_channels.saturating_sub(extra)),
            ),
            Architecture::Sr3Prior(c) => Architecture::Sr3Prior(PriorFlowConfig {
                flow: c
                    .flow
                    .clone()
                    .with_conditioning(Conditioning::None)
                    .with_in_channels(c.flow.in_channels.saturating_sub(extra)),
                prior: c.prior.clone(),
            }),
        }
    }

    /// Whether weights of `file`'s architecture can start a run of this one:
    /// the same architecture, or (for a noise-aware one) the same network
    /// without conditioning, which [`Architecture::widen_unconditioned`]
    /// extends, a narrower SID U-Net, or (for a flow with a prior) the
    /// same field without it ([`PriorFlowConfig::starts_from`]).
    pub fn can_start_from(&self, file: &Architecture) -> bool {
        let narrower = self.narrower_sid(file).is_some();
        let prior_added = matches!(
            (self, file),
            (Architecture::Sr3Prior(p), Architecture::Sr3(f)) if p.starts_from(f)
        );
        let file = same_tensors_json(file);
        narrower
            || prior_added
            || file == same_tensors_json(self)
            || (self.conditioning().extra_channels() > 0
                && file == same_tensors_json(&self.unconditioned()))
    }

    /// The two configurations when `file` is this SID U-Net at a smaller
    /// width and otherwise the same network (what [`widen`] starts a wider
    /// run from).
    fn narrower_sid<'a>(
        &'a self,
        file: &'a Architecture,
    ) -> Option<(&'a SidUnetConfig, &'a SidUnetConfig)> {
        match (file, self) {
            (Architecture::SidUnet(narrow), Architecture::SidUnet(wide))
                if narrow.width < wide.width
                    && same_tensors_json(&Architecture::SidUnet(
                        narrow.clone().with_width(wide.width),
                    )) == same_tensors_json(self) =>
            {
                Some((narrow, wide))
            }
            _ => None,
        }
    }

    /// Make the tensors of `file`'s network (read from an `--init` file) fit
    /// this one, the run's, whose freshly seeded network is `fresh`: as they
    /// are, widened to take the noise planes ([`Self::widen_unconditioned`]),
    /// given a prior ([`PriorFlowConfig::add_prior`]), or written into the
    /// old channels of a wider SID U-Net ([`widen`]).
    pub(crate) fn adapt_start<B: Backend>(
        &self,
        file: &Architecture,
        tensors: &mut BTreeMap<String, NamedTensor>,
        fresh: &Net<B>,
    ) -> std::result::Result<StartAdapted, Mismatch> {
        if self.widen_unconditioned(file, tensors) {
            return Ok(StartAdapted::Conditioned);
        }
        if let (Architecture::Sr3Prior(p), Architecture::Sr3(f)) = (self, file) {
            if p.add_prior(f, tensors, &fresh.parameters()) {
                return Ok(StartAdapted::PriorAdded);
            }
        }
        if let Some((narrow, wide)) = self.narrower_sid(file) {
            let mut out = fresh.parameters();
            widen::widen(
                &narrow.channel_layout(),
                &wide.channel_layout(),
                tensors,
                &mut out,
            )?;
            *tensors = out;
            return Ok(StartAdapted::Widened {
                from: narrow.width,
                to: wide.width,
            });
        }
        Ok(StartAdapted::AsIs)
    }

    /// Make the tensors of an unconditioned network (`file`, this network
    /// without its conditioning) fit this noise-aware one: the input
    /// convolution gains the conditioning's input channels, with zero
    /// weights, after the four noisy planes. The widened network computes
    /// exactly what the unconditioned one did (the new planes are multiplied
    /// by zero) and training then learns to use them: fine-tuning a trained
    /// blind model costs far fewer steps than training a noise-aware one from
    /// scratch. False (tensors untouched) when `file` is not that network.
    pub fn widen_unconditioned(
        &self,
        file: &Architecture,
        tensors: &mut BTreeMap<String, NamedTensor>,
    ) -> bool {
        let extra = self.conditioning().extra_channels();
        if extra == 0 || same_tensors_json(file) != same_tensors_json(&self.unconditioned()) {
            return false;
        }
        match tensors.get_mut(self.spec().input_conv()) {
            Some(t) => insert_zero_inputs(t, 4, extra),
            None => false,
        }
    }

    /// A freshly initialised network of this architecture. Records come from
    /// files: what pgrf's 4-plane pipeline cannot run is refused before
    /// anything is built.
    pub fn init<B: Backend>(&self, device: &B::Device) -> Result<Net<B>> {
        self.spec().check()?;
        Ok(match self {
            Architecture::SidUnet(c) => Net::Spc(c.init(device)),
            Architecture::Sr3(c) => Net::Pgrf(c.init(device)?),
            Architecture::Sr3Prior(c) => Net::Pgrf(c.init(device)?),
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

/// How an `--init` file's weights were made to fit the run's network
/// (`Architecture::adapt_start`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StartAdapted {
    /// The same network: loaded as it is.
    AsIs,
    /// Its unconditioned form: the noise planes' input weights start at zero.
    Conditioned,
    /// The same flow without a prior: the prior's planes are read through
    /// zero weights and the last layer starts at zero (the network samples
    /// the prior's restoration).
    PriorAdded,
    /// The same SID U-Net at width `from`, written into the old channels of
    /// width `to`.
    Widened {
        /// The file's width.
        from: usize,
        /// The run's width.
        to: usize,
    },
}

/// The noisy input as a network reads it: every caller hands the amplified
/// capture clipped at white only, and a network that does not keep values
/// below black (`keep_below_black` false: SID's convention, every file
/// before issue 51) gets them clamped at 0 here, the one place that
/// convention lives.
pub fn input_as_read<B: Backend>(keep_below_black: bool, noisy: Tensor<B, 4>) -> Tensor<B, 4> {
    if keep_below_black {
        noisy
    } else {
        noisy.clamp_min(0.0)
    }
}

/// Give the convolution weight `t` (`[out, in, kh, kw]`) `count` more
/// input channels at channel `at`, with zero weights: the network computes
/// what it did, the new planes multiplied by zero. False (untouched) when
/// `t` is not such a weight or has fewer than `at` input channels.
fn insert_zero_inputs(t: &mut NamedTensor, at: usize, count: usize) -> bool {
    let [o, i, kh, kw] = t.shape[..] else {
        return false;
    };
    if i < at || t.values.len() != o * i * kh * kw {
        return false;
    }
    let k = kh * kw;
    let mut values = Vec::with_capacity(o * (i + count) * k);
    for row in t.values.chunks_exact(i * k) {
        values.extend_from_slice(&row[..at * k]);
        values.extend(std::iter::repeat_n(0.0f32, count * k));
        values.extend_from_slice(&row[at * k..]);
    }
    *t = NamedTensor {
        shape: vec![o, i + count, kh, kw],
        values,
    };
    true
}

/// The record of `a` as JSON without what leaves its tensors as they are:
/// whether values below black are kept changes what the input holds, not
/// the network, so weights trained either way can start a run of the other.
fn same_tensors_json(a: &Architecture) -> Option<serde_json::Value> {
    let mut v = serde_json::to_value(a).ok()?;
    if let Some(c) = v.get_mut("config").and_then(|c| c.as_object_mut()) {
        c.remove("keep_below_black");
        // A flow with a prior: the field's and the prior's own records.
        for part in ["flow", "prior"] {
            if let Some(p) = c.get_mut(part).and_then(|p| p.as_object_mut()) {
                p.remove("keep_below_black");
            }
        }
    }
    Some(v)
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
    ) -> std::result::Result<Net<B>, Mismatch> {
        Ok(match self {
            Net::Spc(n) => Net::Spc(named::assign(n, tensors, device)?),
            Net::Pgrf(n) => Net::Pgrf(named::assign(n, tensors, device)?),
        })
    }

    /// Whether the network is sampled from start noise X0 (the flow model).
    pub(crate) fn sampled(&self) -> bool {
        matches!(self, Net::Pgrf(_))
    }

    /// The flow network with its statistics taken over windows of `side`
    /// ([`Sr3Unet::with_window`]; 0: whole inputs); the denoiser, which has
    /// no statistics, unchanged.
    pub(crate) fn with_window(self, side: usize) -> std::result::Result<Net<B>, ArchFault> {
        Ok(match self {
            Net::Pgrf(n) => Net::Pgrf(n.with_window(side)?),
            spc => spc,
        })
    }

    /// The window side of [`Net::with_window`] (0: none).
    pub(crate) fn window(&self) -> usize {
        match self {
            Net::Pgrf(n) => n.window(),
            Net::Spc(_) => 0,
        }
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
    /// How the network is told its input's noise level.
    pub(crate) fn conditioning(&self) -> Conditioning {
        match self {
            Net::Spc(n) => n.conditioning(),
            Net::Pgrf(n) => n.conditioning(),
        }
    }

    /// Whether the network reads values below black as recorded.
    pub(crate) fn keeps_below_black(&self) -> bool {
        match self {
            Net::Spc(n) => n.keeps_below_black(),
            Net::Pgrf(n) => n.keeps_below_black(),
        }
    }

    /// The noisy input as this network reads it ([`input_as_read`]).
    pub(crate) fn as_read(&self, noisy: Tensor<B, 4>) -> Tensor<B, 4> {
        input_as_read(self.keeps_below_black(), noisy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::Cpu;
    use crate::condition::NoiseLevel;
    use crate::config::LossRule;
    use crate::config::TrainConfig;
    use burn::tensor::{Distribution, TensorData};

    fn config(conditioning: Conditioning) -> TrainConfig {
        TrainConfig {
            width: Some(4),
            inner_channels: Some(8),
            channel_mults: Some(vec![1, 2]),
            res_blocks: Some(1),
            attn_levels: Some(vec![]),
            residual: true,
            conditioning,
            ..TrainConfig::default()
        }
    }

    fn levels() -> Vec<NoiseLevel> {
        vec![
            NoiseLevel::from_dn(1.53, 3.2, 0.4, 15871.0, 100.0),
            NoiseLevel::from_dn(0.2, 1.5, 0.2, 16383.0, 5.0),
        ]
    }

    /// A blind network's weights start a sigma-map (or log-sigma-map) one
    /// that computes exactly
    /// what the blind one did (the noise planes' input weights are zero),
    /// for both networks; other networks, and the k-sigma transform (no
    /// planes to add), are refused.
    #[test]
    fn widened_blind_weights_restore_as_before() {
        let device = Default::default();
        let n = 2 * 4 * 16 * 16;
        let wave = |f: f32| -> Tensor<Cpu, 4> {
            let v: Vec<f32> = (0..n).map(|i| 0.5 + 0.4 * (f * i as f32).sin()).collect();
            Tensor::from_data(TensorData::new(v, [2, 4, 16, 16]), &device)
        };
        let (x, x0) = (wave(0.37), wave(1.91) - 0.5);
        let blind_cfg = |kind| TrainConfig {
            residual: false,
            ..config(kind)
        };
        let cases = [Method::Spc, Method::Pgrf]
            .into_iter()
            .flat_map(|m| [Conditioning::SigmaMap, Conditioning::LogSigmaMap].map(|k| (m, k)));
        for (method, kind) in cases {
            let blind = blind_cfg(Conditioning::None).architecture(method).unwrap();
            let aware = blind_cfg(kind).architecture(method).unwrap();
            assert!(aware.can_start_from(&blind) && aware.can_start_from(&aware));
            assert!(!blind.can_start_from(&aware), "{method:?}");
            let ksigma = blind_cfg(Conditioning::KSigma)
                .architecture(method)
                .unwrap();
            assert!(!ksigma.can_start_from(&blind), "{method:?}");
            let wider = TrainConfig {
                width: Some(8),
                inner_channels: Some(16),
                ..blind_cfg(Conditioning::None)
            }
            .architecture(method)
            .unwrap();
            assert!(!aware.can_start_from(&wider), "{method:?}");

            let net = blind.init_seeded::<Cpu>(&device, 36).unwrap();
            let mut tensors = net.parameters();
            assert!(!aware.widen_unconditioned(&wider, &mut tensors));
            assert!(aware.widen_unconditioned(&blind, &mut tensors));
            let widened = aware
                .init::<Cpu>(&device)
                .unwrap()
                .assign(&tensors, &device)
                .unwrap();
            let a = net.restore(x.clone(), &[], x0.clone(), 0.5);
            let b = widened.restore(x.clone(), &levels(), x0.clone(), 0.5);
            let scale: f32 = a.clone().abs().max().into_scalar();
            let d: f32 = (a - b).abs().max().into_scalar();
            assert!(scale > 1e-3, "{method:?}: output {scale}");
            assert!(
                d <= 1e-5 * scale.max(1.0),
                "{method:?} {kind:?}: widened net differs by {d}"
            );
        }
    }

    /// Values below black reach a network that keeps them and come back
    /// out of it: a fresh residual network (identity) restores a capture
    /// whose mean is below black to the same negative mean, while one that
    /// reads the input clamped (every file before issue 51) restores the
    /// clamp. Weights trained either way start a run of the other.
    #[test]
    fn values_below_black_survive_a_network_that_keeps_them() {
        let device = Default::default();
        // Mean -0.02: a dark capture whose black the metadata puts too high.
        let x =
            Tensor::<Cpu, 4>::random([2, 4, 16, 16], Distribution::Normal(-0.02, 0.05), &device);
        let x0 = Tensor::<Cpu, 4>::zeros([2, 4, 16, 16], &device);
        let x_mean: f32 = x.clone().mean().into_scalar();
        let clamped_mean: f32 = x.clone().clamp_min(0.0).mean().into_scalar();
        assert!(
            x_mean < -0.015 && clamped_mean > 0.01,
            "{x_mean} {clamped_mean}"
        );
        for method in [Method::Spc, Method::Pgrf] {
            for keep in [true, false] {
                let arch = TrainConfig {
                    keep_below_black: keep,
                    ..config(Conditioning::LogSigmaMap)
                }
                .architecture(method)
                .unwrap();
                assert_eq!(arch.keeps_below_black(), keep);
                let net = arch.init_seeded::<Cpu>(&device, 3).unwrap();
                let y = net.restore(x.clone(), &levels(), x0.clone(), 0.5);
                let mean: f32 = y.mean().into_scalar();
                let want = if keep { x_mean } else { clamped_mean };
                assert!(
                    (mean - want).abs() < 2e-4,
                    "{method:?} keep {keep}: mean {mean}, want {want}"
                );
            }
            let keep = TrainConfig {
                keep_below_black: true,
                ..config(Conditioning::LogSigmaMap)
            }
            .architecture(method)
            .unwrap();
            let clamp = config(Conditioning::LogSigmaMap)
                .architecture(method)
                .unwrap();
            assert!(keep.can_start_from(&clamp) && clamp.can_start_from(&keep));
        }
    }

    /// Every conditioning of both networks: the record names it, the first
    /// layer reads its planes, the restored batch and the loss have the
    /// plain shapes, and a fresh residual network restores its input
    /// (the k-sigma map and its inverse cancel).
    #[test]
    fn conditioned_networks_take_their_planes_and_give_four() {
        let device = Default::default();
        let x = Tensor::<Cpu, 4>::random([2, 4, 16, 16], Distribution::Uniform(0.0, 1.0), &device);
        let clean =
            Tensor::<Cpu, 4>::random([2, 4, 16, 16], Distribution::Uniform(0.0, 1.0), &device);
        for kind in [
            Conditioning::None,
            Conditioning::SigmaMap,
            Conditioning::KSigma,
            Conditioning::LogSigmaMap,
        ] {
            for method in [Method::Spc, Method::Pgrf] {
                let arch = config(kind).architecture(method).unwrap();
                assert_eq!(arch.conditioning(), kind);
                let json = serde_json::to_value(&arch).unwrap();
                assert_eq!(json["config"]["conditioning"], kind.name());
                let base = if method == Method::Spc { 4 } else { 8 };
                assert_eq!(
                    json["config"]["in_channels"],
                    base + kind.extra_channels(),
                    "{kind:?} {method:?}"
                );
                let net = arch.init_seeded::<Cpu>(&device, 1).unwrap();
                let x0 = Tensor::<Cpu, 4>::zeros([2, 4, 16, 16], &device);
                let y = net.restore(x.clone(), &levels(), x0.clone(), 0.5);
                assert_eq!(y.dims(), [2, 4, 16, 16]);
                let d: f32 = (y - x.clone()).abs().max().into_scalar();
                // A fresh residual field's two-stage sample is T exactly at
                // both stages up to the flow's arithmetic.
                assert!(
                    d < 2e-4,
                    "{kind:?} {method:?}: fresh residual net moved the input by {d}"
                );
                let t =
                    Tensor::<Cpu, 1>::from_data(TensorData::new(vec![0.2f32, 0.7], [2]), &device);
                let loss = net.loss(
                    x.clone(),
                    clean.clone(),
                    &levels(),
                    LossRule::default(),
                    || x0.clone(),
                    || t.clone(),
                );
                let v: f32 = loss.into_scalar();
                assert!(v.is_finite() && v > 0.0, "{kind:?} {method:?}: loss {v}");
            }
        }
    }

    /// The denoiser's loss is taken in input units whatever the domain: a
    /// fresh residual network's loss is |T - X1| for every conditioning.
    #[test]
    fn the_denoiser_loss_is_in_input_units_for_every_conditioning() {
        let device = Default::default();
        let x = Tensor::<Cpu, 4>::random([2, 4, 16, 16], Distribution::Uniform(0.0, 1.0), &device);
        let clean =
            Tensor::<Cpu, 4>::random([2, 4, 16, 16], Distribution::Uniform(0.0, 1.0), &device);
        let want: f32 = (x.clone() - clean.clone()).abs().mean().into_scalar();
        for kind in [
            Conditioning::None,
            Conditioning::SigmaMap,
            Conditioning::KSigma,
            Conditioning::LogSigmaMap,
        ] {
            let net = config(kind)
                .architecture(Method::Spc)
                .unwrap()
                .init_seeded::<Cpu>(&device, 2)
                .unwrap();
            let zero = Tensor::<Cpu, 4>::zeros([2, 4, 16, 16], &device);
            let t = Tensor::<Cpu, 1>::zeros([2], &device);
            let got: f32 = net
                .loss(
                    x.clone(),
                    clean.clone(),
                    &levels(),
                    LossRule::default(),
                    || zero.clone(),
                    || t.clone(),
                )
                .into_scalar();
            assert!(
                (got - want).abs() < 1e-4 * want,
                "{kind:?}: {got} vs {want}"
            );
        }
    }
}
