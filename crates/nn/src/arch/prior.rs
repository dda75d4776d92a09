//! A flow that starts from a denoiser's restoration (issue 51, lever 5;
//! PMRF's idea, Ohayon et al. 2025, fitted to pgrf's residual field): the
//! velocity field reads, besides T and the conditioning's planes, the
//! restoration P of a frozen SPC denoiser (the "prior", stored in the same
//! weight file under `prior.`), and its residual parametrisation corrects P
//! instead of T: v = (P + net(Xt, T, P, t) - Xt) / max(1 - t, 0.1).
//!
//! Why: the paper's flow has to find the whole restoration from the noisy
//! capture, and pgrf's small CPU-trained flows stayed 0.3-0.8 dB below the
//! SPC (MODELS.md). With the prior, a field whose last layer is zero
//! samples P exactly at both stages of the two-stage sampler (XZ = P, and
//! XM = X0 + (P - Xt2) / (1 - t2) = P), so training starts from the SPC's
//! score and only has to add what the posterior mean lost.
//!
//! The prior is never trained: its restoration is detached before the field
//! reads it, its parameters take no gradient and the moving average of the
//! weights leaves them as they are ([`is_prior`]).

use super::network::NetworkConfig;
use super::sid_unet::SidUnetConfig;
use super::sr3::{Sr3Config, Sr3Unet};
use super::{input_as_read, Extras, Method};
use crate::condition::{Conditioned, Conditioning, NoiseLevel};
use crate::error::{ArchFault, Result as NnResult};
use crate::named::{Mismatch, NamedTensor, TensorFault};
use crate::ops::PgrfOps;
use burn::module::Module;
use burn::tensor::backend::Backend;
use burn::tensor::Tensor;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The prefix of the prior's parameters in the flow's weight file.
const PRIOR: &str = "prior.";

/// Whether parameter `name` belongs to the frozen prior.
pub(crate) fn is_prior(name: &str) -> bool {
    name.starts_with(PRIOR)
}

/// A flow model that starts from a denoiser's restoration: in a weight
/// file's record as `"arch": "sr3-prior"`, `"config": {"flow": ..,
/// "prior": ..}`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PriorFlowConfig {
    /// The velocity field; its input planes are T, the conditioning's
    /// planes, the prior's restoration (4) and Xt (4).
    pub flow: Sr3Config,
    /// The frozen SPC denoiser whose restoration the field corrects.
    pub prior: SidUnetConfig,
}

impl PriorFlowConfig {
    /// `flow` (as `pgrf train pgrf` builds it without a prior) reading
    /// `prior`'s restoration too: four more input planes.
    pub fn new(flow: Sr3Config, prior: SidUnetConfig) -> PriorFlowConfig {
        let planes = 12 + flow.conditioning.extra_channels();
        PriorFlowConfig {
            flow: flow.with_in_channels(planes),
            prior,
        }
    }

    /// The field without the prior (the file a run may start from:
    /// [`PriorFlowConfig::add_prior`]).
    pub(crate) fn without_prior(&self) -> Sr3Config {
        let planes = self.flow.in_channels.saturating_sub(4);
        self.flow.clone().with_in_channels(planes)
    }

    /// Refuse what cannot run: the field's own checks with four more
    /// planes, the prior's, and a prior that needs a noise level the field
    /// is not given.
    fn validate(&self) -> Result<(), ArchFault> {
        let planes = 12 + self.flow.conditioning.extra_channels();
        self.flow
            .validate_planes(planes, "T, the prior's restoration and Xt")?;
        self.prior
            .fault()
            .map_err(|e| ArchFault::Prior(Box::new(e)))?;
        if self.prior.conditioning.needs_level() && !self.flow.conditioning.needs_level() {
            return Err(ArchFault::PriorLevel(self.prior.conditioning));
        }
        Ok(())
    }

    /// A network of this configuration with burn's default initialisation
    /// (the prior's weights too: loading a run's prior or a file replaces
    /// them); the prior takes no gradient.
    pub fn init<B: Backend>(&self, device: &B::Device) -> Result<Sr3Unet<B>, ArchFault> {
        self.validate()?;
        let mut net = self.flow.build(device);
        net.prior = Some(self.prior.init(device).no_grad());
        Ok(net)
    }

    /// Whether `file` is this field without the prior (what
    /// `--init` with a prior starts a run from); whether values
    /// below black are kept does not matter (`super::same_tensors_json`).
    pub fn starts_from(&self, file: &Sr3Config) -> bool {
        let same = |a: &Sr3Config| super::same_tensors_json(&super::Architecture::Sr3(a.clone()));
        let file = same(file);
        file.is_some() && file == same(&self.without_prior())
    }

    /// Make the tensors of `file`'s field (this one without the prior,
    /// [`PriorFlowConfig::without_prior`]) fit this one: the first
    /// convolution gains the prior's four input planes after T and the
    /// conditioning's (zero weights), the last layer starts at zero, so that
    /// the network samples the prior's restoration exactly, and the prior's
    /// tensors are `fresh`'s (the run loads its prior after). False when
    /// `file` is not that field.
    pub(crate) fn add_prior(
        &self,
        file: &Sr3Config,
        tensors: &mut BTreeMap<String, NamedTensor>,
        fresh: &BTreeMap<String, NamedTensor>,
    ) -> bool {
        if !self.starts_from(file) {
            return false;
        }
        let at = 4 + self.flow.conditioning.extra_channels();
        let Some(first) = tensors.get_mut("first.weight") else {
            return false;
        };
        if !super::insert_zero_inputs(first, at, 4) {
            return false;
        }
        for name in ["final_conv.weight", "final_conv.bias"] {
            if let Some(t) = tensors.get_mut(name) {
                t.values.iter_mut().for_each(|v| *v = 0.0);
            }
        }
        for (name, t) in fresh.iter().filter(|(n, _)| is_prior(n)) {
            tensors.insert(name.clone(), t.clone());
        }
        true
    }
}

impl NetworkConfig for PriorFlowConfig {
    fn method(&self) -> Method {
        Method::Pgrf
    }

    fn describe(&self) -> String {
        format!(
            "{} correcting an {}",
            self.flow.describe(),
            self.prior.describe()
        )
    }

    fn check(&self) -> NnResult<()> {
        Ok(self.validate()?)
    }

    fn min_params(&self) -> f64 {
        self.flow.min_params() + self.prior.min_params()
    }

    /// The prior runs first and only its four output planes stay.
    fn bytes_per_pixel(&self) -> f64 {
        self.flow
            .bytes_per_pixel()
            .max(self.prior.bytes_per_pixel())
            + 16.0
    }

    fn attention_tokens(&self, h: usize, w: usize) -> usize {
        self.flow.attention_tokens(h, w)
    }

    /// Both are powers of two: the larger is a multiple of the smaller.
    fn side_multiple(&self) -> usize {
        NetworkConfig::side_multiple(&self.flow).max(self.prior.side_multiple())
    }

    fn tile_cap(&self, trained_patch: Option<usize>) -> usize {
        self.flow
            .tile_cap(trained_patch)
            .min(self.prior.tile_cap(trained_patch))
    }

    fn sampled(&self) -> bool {
        true
    }

    fn extras(&self, time_max: f32) -> Extras {
        self.flow.extras(time_max)
    }

    fn residual(&self) -> bool {
        self.flow.residual
    }

    fn conditioning(&self) -> Conditioning {
        self.flow.conditioning
    }

    fn keeps_below_black(&self) -> bool {
        self.flow.keep_below_black
    }

    fn input_conv(&self) -> &'static str {
        "first.weight"
    }
}

impl<B: PgrfOps> Sr3Unet<B> {
    /// The condition the field reads: `c`'s input (T and the
    /// conditioning's planes, in the field's domain), followed, for a flow
    /// with a prior, by the prior's restoration of `noisy` (the amplified
    /// capture as every caller hands it, clipped at white only; item i at
    /// `levels[i]`) in that domain, detached. Made once per batch: the
    /// samplers evaluate the field twice or more on the same condition.
    pub fn condition(
        &self,
        c: &Conditioned<B>,
        noisy: Tensor<B, 4>,
        levels: &[NoiseLevel],
    ) -> Tensor<B, 4> {
        let Some(prior) = &self.prior else {
            return c.input.clone();
        };
        let read = input_as_read(prior.keeps_below_black(), noisy);
        let pc = Conditioned::new(prior.conditioning(), read, levels);
        let restored = pc.input_units_of(prior.forward(pc.input.clone())).detach();
        Tensor::cat(vec![c.input.clone(), c.domain_of(restored)], 1)
    }
}

impl<B: Backend> Sr3Unet<B> {
    /// This field reading the restoration of `prior` (its weights
    /// `tensors`, named as in the prior's own file), which takes no
    /// gradient; the error lists what does not fit.
    pub(crate) fn with_prior_weights(
        mut self,
        tensors: &BTreeMap<String, NamedTensor>,
        device: &B::Device,
    ) -> Result<Self, Mismatch> {
        let prior = self.prior.take().ok_or(TensorFault::NoPrior)?;
        self.prior = Some(crate::named::assign(prior, tensors, device)?.no_grad());
        Ok(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arch::{Architecture, Net, StartAdapted};
    use crate::backend::{Cpu, CpuTrain};
    use crate::config::{LossRule, TrainConfig};
    use crate::ema::Ema;
    use crate::weights::{NoiseSource, WeightMeta};
    use burn::optim::{AdamConfig, GradientsParams, Optimizer};
    use burn::tensor::TensorData;

    /// A small noise-aware residual field (without a prior: 12 planes).
    fn flow() -> Sr3Config {
        Sr3Config::new()
            .with_inner_channels(8)
            .with_channel_mults(vec![1, 2])
            .with_res_blocks(1)
            .with_attn_levels(vec![])
            .with_norm_groups(4)
            .with_residual(true)
            .with_conditioning(Conditioning::LogSigmaMap)
            .with_in_channels(12)
    }

    fn denoiser() -> SidUnetConfig {
        SidUnetConfig::new()
            .with_width(4)
            .with_residual(true)
            .with_conditioning(Conditioning::LogSigmaMap)
            .with_in_channels(8)
    }

    fn with_prior() -> Architecture {
        Architecture::Sr3Prior(PriorFlowConfig::new(flow(), denoiser()))
    }

    fn levels() -> Vec<NoiseLevel> {
        vec![NoiseLevel::from_dn(1.53, 3.2, 0.4, 15871.0, 100.0)]
    }

    /// A seeded noisy-looking batch `(1, 4, 16, 16)` with values below 0.
    fn batch<B: Backend>(seed: u32) -> Tensor<B, 4> {
        let v: Vec<f32> = (0..4 * 16 * 16)
            .map(|i| 0.2 + 0.3 * ((i as u32 * 7 + seed) as f32 * 0.61).sin())
            .collect();
        Tensor::from_data(TensorData::new(v, [1, 4, 16, 16]), &Default::default())
    }

    /// A seeded SPC denoiser and its tensors.
    fn spc() -> (Net<Cpu>, BTreeMap<String, NamedTensor>) {
        let net = Architecture::SidUnet(denoiser())
            .init_seeded::<Cpu>(&Default::default(), 5)
            .unwrap();
        let tensors = net.parameters();
        (net, tensors)
    }

    fn values(t: Tensor<Cpu, 4>) -> Vec<f32> {
        t.into_data().to_vec().unwrap()
    }

    fn max_diff(a: &[f32], b: &[f32]) -> f32 {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f32::max)
    }

    /// The flow `arch` with the seeded SPC as its prior.
    fn flow_with_spc(arch: &Architecture) -> Net<Cpu> {
        let device = Default::default();
        let Net::Pgrf(f) = arch.init_seeded::<Cpu>(&device, 3).unwrap() else {
            panic!("a flow")
        };
        Net::Pgrf(f.with_prior_weights(&spc().1, &device).unwrap())
    }

    /// A fresh field (last layer zero) samples the prior's restoration:
    /// the two-stage sampler's XZ = X0 + (P - X0) and XM = X0 + (P - Xt2)
    /// / (1 - t2) are P up to rounding (1e-5 here; values about 1). The
    /// restoration differs from the noisy input by far more, so the test
    /// would see the field correcting T instead.
    #[test]
    fn a_fresh_field_samples_the_prior_restoration() {
        let net = flow_with_spc(&with_prior());
        let x0 = batch::<Cpu>(99) * 3.0;
        let flow = values(net.restore(batch(1), &levels(), x0.clone(), 0.4));
        let prior = values(spc().0.restore(batch(1), &levels(), x0, 0.0));
        assert!(
            max_diff(&flow, &prior) < 1e-5,
            "{}",
            max_diff(&flow, &prior)
        );
        assert!(max_diff(&prior, &values(batch(1))) > 0.01);
    }

    /// A trained field without a prior starts a run of the same field with
    /// one: T's, the noise planes' and Xt's weights are kept, the prior's
    /// planes get zero weights after the noise planes, the last layer is
    /// zeroed, so the result samples the prior's restoration.
    #[test]
    fn a_flow_without_a_prior_starts_one_that_samples_the_prior() {
        let device = Default::default();
        let arch = with_prior();
        let file = Architecture::Sr3(flow());
        assert!(arch.can_start_from(&file));
        let other = Architecture::Sr3(flow().with_inner_channels(16).with_norm_groups(8));
        assert!(!arch.can_start_from(&other));
        let mut trained = file.init_seeded::<Cpu>(&device, 8).unwrap().parameters();
        let last = trained.get_mut("final_conv.weight").unwrap();
        last.values.iter_mut().for_each(|v| *v = 0.01);
        let before = trained["first.weight"].clone();
        let fresh = arch.init_seeded::<Cpu>(&device, 3).unwrap();
        let how = arch.adapt_start(&file, &mut trained, &fresh).unwrap();
        assert_eq!(how, StartAdapted::PriorAdded);
        let first = &trained["first.weight"];
        // 16 planes of 3 x 3: T, noise, prior, Xt (the file's: 12).
        assert_eq!(first.shape, vec![8, 16, 3, 3]);
        for o in 0..8 {
            let (new, old) = (&first.values[o * 144..], &before.values[o * 108..]);
            assert_eq!(&new[..72], &old[..72], "T and noise planes of output {o}");
            assert!(new[72..108].iter().all(|&v| v == 0.0));
            assert_eq!(&new[108..144], &old[72..108], "Xt planes of output {o}");
        }
        let Net::Pgrf(f) = fresh.assign(&trained, &device).unwrap() else {
            panic!("a flow")
        };
        let net = Net::Pgrf(f.with_prior_weights(&spc().1, &device).unwrap());
        let x0 = batch::<Cpu>(5);
        let flow = values(net.restore(batch(2), &levels(), x0.clone(), 0.3));
        let prior = values(spc().0.restore(batch(2), &levels(), x0, 0.0));
        assert!(
            max_diff(&flow, &prior) < 1e-5,
            "{}",
            max_diff(&flow, &prior)
        );
    }

    /// Optimiser steps on the flow's loss change the field and leave the
    /// prior bit for bit; so does the moving average of the weights.
    #[test]
    fn training_leaves_the_prior_as_loaded() {
        let device = Default::default();
        let arch = with_prior();
        let Net::Pgrf(f) = arch.init_seeded::<CpuTrain>(&device, 3).unwrap() else {
            panic!("a flow")
        };
        let mut net = Net::Pgrf(f.with_prior_weights(&spc().1, &device).unwrap());
        let start = net.parameters();
        let mut ema = Ema::start(0.5, start.clone());
        let mut optim = AdamConfig::new().init();
        for step in 0..3 {
            let loss = net.loss(
                batch(1),
                batch::<CpuTrain>(2) * 0.5,
                &levels(),
                LossRule::default(),
                || batch::<CpuTrain>(3),
                || Tensor::from_floats([0.3], &device),
            );
            let grads = GradientsParams::from_grads(loss.backward(), &net);
            net = optim.step(1e-2, net, grads);
            ema.update(step, &net.parameters());
        }
        let end = net.parameters();
        let averaged = ema
            .network::<Cpu>(&arch, &Default::default())
            .unwrap()
            .parameters();
        let mut changed = 0;
        for (name, t) in &start {
            if is_prior(name) {
                assert_eq!(t.values, end[name].values, "{name} trained");
                assert_eq!(t.values, averaged[name].values, "{name} averaged");
            } else if t.values != end[name].values {
                changed += 1;
            }
        }
        assert!(start.keys().any(|n| is_prior(n)));
        assert!(changed > 10, "{changed} field tensors changed");
    }

    /// The weight file holds the field and the prior: its record says
    /// `sr3-prior`, and the loaded model restores the same bits.
    #[test]
    fn the_weight_file_holds_the_prior() {
        let device = Default::default();
        let arch = with_prior();
        let net = flow_with_spc(&arch);
        let dir = std::env::temp_dir().join(format!("pgrf-nn-prior-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("flow.safetensors");
        net.save(&p, &WeightMeta::new(arch, NoiseSource::default()))
            .unwrap();
        let (back, meta) = crate::model::load::<Cpu>(&p, &device).unwrap();
        let record = serde_json::to_value(&meta.arch).unwrap();
        assert_eq!(record["arch"], "sr3-prior");
        assert_eq!(record["config"]["prior"]["width"], 4);
        assert!(meta.arch.describe().contains("correcting an SPC denoiser"));
        let x0 = batch::<Cpu>(7);
        let a = values(net.restore(batch(4), &levels(), x0.clone(), 0.4));
        let b = values(back.restore(batch(4), &levels(), x0, 0.4));
        assert_eq!(a, b);
        std::fs::remove_dir_all(&dir).ok();
    }

    /// `prior` in a run's configuration: an SPC file makes the flow read
    /// it; a flow file, or a prior for the denoiser, is refused.
    #[test]
    fn the_configuration_names_its_prior() {
        let device = Default::default();
        let dir = std::env::temp_dir().join(format!("pgrf-nn-prior-cfg-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let spc_file = dir.join("spc.safetensors");
        let arch = Architecture::SidUnet(denoiser());
        spc()
            .0
            .save(&spc_file, &WeightMeta::new(arch, NoiseSource::default()))
            .unwrap();
        let c = TrainConfig {
            prior: Some(spc_file.clone()),
            inner_channels: Some(8),
            channel_mults: Some(vec![1, 2]),
            res_blocks: Some(1),
            attn_levels: Some(vec![]),
            residual: true,
            conditioning: Conditioning::LogSigmaMap,
            ..TrainConfig::default()
        };
        let Architecture::Sr3Prior(p) = c.architecture(crate::Method::Pgrf).unwrap() else {
            panic!("a flow with a prior")
        };
        assert_eq!((p.flow.in_channels, p.prior.width), (16, 4));
        let e = c.architecture(crate::Method::Spc).unwrap_err().to_string();
        assert!(e.contains("--prior starts a flow model"), "{e}");
        let flow_file = dir.join("flow.safetensors");
        let f = Architecture::Sr3(flow());
        f.init::<Cpu>(&device)
            .unwrap()
            .save(&flow_file, &WeightMeta::new(f, NoiseSource::default()))
            .unwrap();
        let bad = TrainConfig {
            prior: Some(flow_file),
            ..c
        };
        let e = bad
            .architecture(crate::Method::Pgrf)
            .unwrap_err()
            .to_string();
        assert!(e.contains("not an SPC denoiser"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
