//! A network applied to a batch, for either network: the restored batch
//! (the denoiser's one pass or the flow's sampler) and the training loss.
//! Kept above [`crate::arch`] (which holds the networks and their
//! configurations), [`crate::flow`] (the path and samplers) and
//! [`crate::loss`], so that none of those depends on another in a loop.

use crate::arch::Net;
use crate::condition::{Conditioned, Conditioning, NoiseLevel};
use crate::config::LossRule;
use crate::flow::flow_loss;
use crate::flow::sample::{two_stage, Sampler};
use crate::loss::{batch_loss, denoiser_loss};
use crate::ops::PgrfOps;
use burn::tensor::Tensor;

impl<B: PgrfOps> Net<B> {
    /// The denoised batch: one pass for SPC, the two-stage sampler at `t2`
    /// for the flow model. `noisy` is T, `(n, 4, h, w)`, item i at noise
    /// level `levels[i]` (unused, and may be empty, by an unconditioned
    /// network); `x0` is X0, same shape (ignored by SPC).
    pub(crate) fn restore(
        &self,
        noisy: Tensor<B, 4>,
        levels: &[NoiseLevel],
        x0: Tensor<B, 4>,
        t2: f32,
    ) -> Tensor<B, 4> {
        let c = Conditioned::new(self.conditioning(), self.as_read(noisy.clone()), levels);
        let y = match self {
            Net::Spc(n) => n.forward(c.input.clone()),
            Net::Pgrf(n) => two_stage(n, n.condition(&c, noisy, levels), x0, t2),
        };
        c.input_units_of(y)
    }

    /// One restored tile `(1, 4, h, w)` from the condition `cond` at noise
    /// level `level` (None only for an unconditioned network): the
    /// denoiser's one pass, or the mean of the flow model's `samples`
    /// samples with `sampler`, sample k starting from `x0(k)` (made one at a
    /// time, so only one start field is held).
    pub(crate) fn restore_tile(
        &self,
        cond: Tensor<B, 4>,
        level: Option<NoiseLevel>,
        samples: usize,
        x0: impl Fn(usize) -> Tensor<B, 4>,
        sampler: Sampler,
    ) -> Tensor<B, 4> {
        let levels: Vec<NoiseLevel> = level.into_iter().collect();
        let c = Conditioned::new(self.conditioning(), self.as_read(cond.clone()), &levels);
        let y = match self {
            Net::Spc(n) => n.forward(c.input.clone()),
            Net::Pgrf(n) => {
                let t = n.condition(&c, cond, &levels);
                let mut acc: Option<Tensor<B, 4>> = None;
                for k in 0..samples {
                    let y = sampler.run(n, t.clone(), x0(k));
                    acc = Some(match acc {
                        None => y,
                        Some(a) => a + y,
                    });
                }
                acc.expect("samples >= 1") / samples as f32
            }
        };
        c.input_units_of(y)
    }

    /// The training loss of a batch: the denoiser's L1 ([`denoiser_loss`]),
    /// or the flow's ([`flow_loss`]) with the start X0 and times t, made only
    /// when the network needs them. Item i is at noise level `levels[i]`
    /// (unused by an unconditioned network). A k-sigma network's denoiser
    /// loss is taken after its output is mapped back, and its flow loss in
    /// the k-sigma domain divided by each item's scale: both in input units,
    /// so that low-noise items (large scales) do not outweigh the rest.
    /// `rule` says which distance and how the items' errors add up
    /// ([`crate::loss::batch_loss`]; the default rule is the plain L1 mean).
    pub(crate) fn loss(
        &self,
        noisy: Tensor<B, 4>,
        clean: Tensor<B, 4>,
        levels: &[NoiseLevel],
        rule: LossRule,
        x0: impl FnOnce() -> Tensor<B, 4>,
        t: impl FnOnce() -> Tensor<B, 1>,
    ) -> Tensor<B, 1> {
        let kind = self.conditioning();
        let raw = noisy.clone();
        let noisy = self.as_read(noisy);
        if kind == Conditioning::None && rule == LossRule::default() {
            return match self {
                Net::Spc(n) => denoiser_loss(n, noisy, clean),
                Net::Pgrf(n) => {
                    let cond = n.condition(&Conditioned::new(kind, noisy, levels), raw, levels);
                    flow_loss(n, cond, clean, x0(), t())
                }
            };
        }
        let c = Conditioned::new(kind, noisy, levels);
        let err = match self {
            Net::Spc(n) => c.input_units_of(n.forward(c.input.clone())) - clean.clone(),
            Net::Pgrf(n) => {
                let x1 = c.domain_of(clean.clone());
                let (x0, t) = (x0(), t());
                let xt = crate::flow::interpolate(x1.clone(), x0.clone(), t.clone());
                let err = x1 - x0 - n.forward(xt, n.condition(&c, raw, levels), t);
                match c.inverse_scale() {
                    Some(s) => err * s,
                    None => err,
                }
            }
        };
        batch_loss(err, rule, levels, &clean)
    }
}
