//! The training losses below the training step ([`crate::step`]) and the
//! flow ([`crate::flow`], whose loss is built on [`l1`]): the distance of a
//! batch and how its items' errors add up ([`batch_loss`], `--loss`,
//! `--item-weight`), and the denoiser's L1.

use crate::arch::sid_unet::SidUnet;
use crate::condition::NoiseLevel;
use crate::config::{Distance, ItemWeight, LossRule};
use crate::ops::PgrfOps;
use burn::tensor::Tensor;

/// Mean absolute error over every element.
pub fn l1<B: PgrfOps>(a: Tensor<B, 4>, b: Tensor<B, 4>) -> Tensor<B, 1> {
    (a - b).abs().mean()
}

/// The smallest per-item error [`ItemWeight::Log`] divides by: 1e-5 of
/// white (its square for the MSE), far below any capture's noise, so an
/// item restored almost exactly cannot take the whole batch's weight.
const LOG_WEIGHT_FLOOR: f32 = 1e-5;

/// The batch's loss from its per-element errors `err` `(n, c, h, w)`: the
/// mean distance (`rule.distance`: absolute or squared) over every element,
/// or each item's mean distance weighted as `rule.weight` says, the weights
/// scaled to a mean of 1 over the batch (so the learning rate means what it
/// meant unweighted). `levels` (one per item) and `clean` (the targets) give
/// each item's noise level for [`ItemWeight::Noise`]; that weight is the
/// inverse of the level's deviation for L1 and of its variance for the MSE,
/// so that both weigh an item's error in units of its noise.
pub fn batch_loss<B: PgrfOps>(
    err: Tensor<B, 4>,
    rule: LossRule,
    levels: &[NoiseLevel],
    clean: &Tensor<B, 4>,
) -> Tensor<B, 1> {
    let (a, floor) = match rule.distance {
        Distance::L1 => (err.abs(), LOG_WEIGHT_FLOOR),
        Distance::Mse => (err.clone() * err, LOG_WEIGHT_FLOOR * LOG_WEIGHT_FLOOR),
    };
    let [n, c, h, w] = a.dims();
    if rule.weight == ItemWeight::None || n < 2 {
        return a.mean();
    }
    let per_item = a.reshape([n, c * h * w]).mean_dim(1).reshape([n]);
    let inverse = match rule.weight {
        ItemWeight::None => unreachable!("returned above"),
        ItemWeight::Noise => {
            let sigma = noise_sigma(levels, clean);
            match rule.distance {
                Distance::L1 => sigma.recip(),
                Distance::Mse => (sigma.clone() * sigma).recip(),
            }
        }
        ItemWeight::Log => (per_item.clone().detach().clamp_min(floor)).recip(),
    };
    let weights = inverse.clone() / inverse.mean();
    (per_item * weights).mean()
}

/// Each item's noise standard deviation at its mean clean level,
/// sqrt(gain E[x] + floor) ([`NoiseLevel`]), shape `(n)`, not tracked.
fn noise_sigma<B: PgrfOps>(levels: &[NoiseLevel], clean: &Tensor<B, 4>) -> Tensor<B, 1> {
    let [n, c, h, w] = clean.dims();
    let device = clean.device();
    let mean = clean
        .clone()
        .detach()
        .reshape([n, c * h * w])
        .mean_dim(1)
        .reshape([n])
        .clamp_min(0.0);
    let pick = |f: fn(&NoiseLevel) -> f32| {
        let v: Vec<f32> = (0..n).map(|i| levels.get(i).map_or(0.0, f)).collect();
        Tensor::<B, 1>::from_floats(v.as_slice(), &device)
    };
    let gain = pick(|l| l.gain);
    let floor = pick(|l| l.floor);
    (gain * mean + floor)
        .clamp_min(LOG_WEIGHT_FLOOR * LOG_WEIGHT_FLOOR)
        .sqrt()
}

/// The denoiser's loss: L1(net(noisy x ratio), clean), `noisy` being the
/// amplified, clamped input and `clean` the target, both `(n, 4, h, w)`
/// packed in [0, 1].
pub fn denoiser_loss<B: PgrfOps>(
    net: &SidUnet<B>,
    noisy: Tensor<B, 4>,
    clean: Tensor<B, 4>,
) -> Tensor<B, 1> {
    l1(net.forward(noisy), clean)
}
