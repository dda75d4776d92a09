//! Single optimisation steps for the two networks, shared by the training
//! loop and by tests that check learning actually happens.
//!
//! - Denoiser (SPC): L1(net(noisy x ratio), clean).
//! - Rectified flow (PGRF): X1 clean, X0 ~ N(0, I), T the noisy condition,
//!   t ~ U(0, 1), Xt = t X1 + (1 - t) X0, loss |X1 - X0 - v(Xt, T, t)|_1;
//!   the path and the loss are [`crate::flow`]'s.

use crate::arch::sid_unet::SidUnet;
use crate::arch::sr3::Sr3Unet;
use crate::flow::flow_loss;
use crate::loss::denoiser_loss;
use crate::ops::PgrfAutodiff;
use burn::optim::{GradientsParams, Optimizer};
use burn::tensor::{ElementConversion, Tensor};

/// One Adam (or other optimiser) step of the denoiser at learning rate `lr`
/// on the batch (`noisy`, `clean`) of [`denoiser_loss`]; returns the updated
/// network and the loss before the update.
pub fn denoiser_step<B: PgrfAutodiff, O: Optimizer<SidUnet<B>, B>>(
    net: SidUnet<B>,
    optim: &mut O,
    noisy: Tensor<B, 4>,
    clean: Tensor<B, 4>,
    lr: f64,
) -> (SidUnet<B>, f32) {
    let loss = denoiser_loss(&net, noisy, clean);
    let value: f32 = loss.clone().into_scalar().elem();
    let grads = GradientsParams::from_grads(loss.backward(), &net);
    (optim.step(lr, net, grads), value)
}

/// One rectified-flow step (Algorithm 1's update): the loss
/// |X1 - X0 - v(Xt, T, t)|_1 of [`crate::flow::flow_loss`] with `cond`
/// T, `x1` X1, `x0` X0 ~ N(0, I) and `t` ~ U(0, 1), the latter two drawn by
/// the caller (so the loop owns the randomness and its seed;
/// [`crate::flow`]). Returns the updated network and the loss before the
/// update.
pub fn flow_step<B: PgrfAutodiff, O: Optimizer<Sr3Unet<B>, B>>(
    net: Sr3Unet<B>,
    optim: &mut O,
    cond: Tensor<B, 4>,
    x1: Tensor<B, 4>,
    x0: Tensor<B, 4>,
    t: Tensor<B, 1>,
    lr: f64,
) -> (Sr3Unet<B>, f32) {
    let loss = flow_loss(&net, cond, x1, x0, t);
    let value: f32 = loss.clone().into_scalar().elem();
    let grads = GradientsParams::from_grads(loss.backward(), &net);
    (optim.step(lr, net, grads), value)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arch::sid_unet::SidUnetConfig;
    use crate::arch::sr3::Sr3Config;
    use crate::condition::NoiseLevel;
    use crate::config::{Distance, ItemWeight, LossRule};
    use crate::loss::batch_loss;
    use burn::backend::{Autodiff, Flex};
    use burn::optim::AdamConfig;
    use burn::tensor::Distribution;

    type B = Autodiff<Flex>;

    /// A smooth clean batch and a noisy copy of it.
    fn batch(device: &burn::tensor::Device<B>) -> (Tensor<B, 4>, Tensor<B, 4>) {
        let (n, h, w) = (2, 32, 32);
        let data: Vec<f32> = (0..n * 4 * h * w)
            .map(|i| {
                let (y, x) = ((i / w) % h, i % w);
                0.5 + 0.3 * ((x as f32) / 5.0).sin() * ((y as f32) / 7.0).cos()
            })
            .collect();
        let clean = Tensor::<B, 1>::from_floats(data.as_slice(), device).reshape([n, 4, h, w]);
        let noise = Tensor::<B, 4>::random([n, 4, h, w], Distribution::Normal(0.0, 0.1), device);
        (clean.clone() + noise, clean)
    }

    /// Two items whose every element errs by `e[i]` (signs alternating).
    fn errors(e: [f32; 2], device: &burn::tensor::Device<B>) -> Tensor<B, 4> {
        let n = 4 * 8 * 8;
        let v: Vec<f32> = (0..2 * n)
            .map(|k| e[k / n] * if k % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        Tensor::<B, 1>::from_floats(v.as_slice(), device)
            .reshape([2, 4, 8, 8])
            .require_grad()
    }

    /// The weighting's value and its gradient, against the formulas: plain
    /// mean; log (harmonic mean of the items' errors, and each item's
    /// gradient times its error equal, so a relative change counts alike);
    /// noise (weights 1/sigma at the items' mean levels, scaled to mean 1).
    #[test]
    fn items_are_weighted_as_stated() {
        let device = Default::default();
        let clean = Tensor::<B, 4>::full([2, 4, 8, 8], 0.25, &device);
        // sigma^2 = gain * 0.25 + floor: 0.1^2 and 0.01^2.
        let levels = [
            NoiseLevel {
                gain: 0.036,
                floor: 0.001,
            },
            NoiseLevel {
                gain: 0.0,
                floor: 1e-4,
            },
        ];
        let e = [0.1f32, 0.001];
        let value = |weight| -> f32 {
            let rule = LossRule {
                distance: Distance::L1,
                weight,
            };
            batch_loss(errors(e, &device), rule, &levels, &clean).into_scalar()
        };
        assert!((value(ItemWeight::None) - 0.0505).abs() < 1e-6);
        let harmonic = 2.0 / (1.0 / 0.1 + 1.0 / 0.001);
        assert!(
            (value(ItemWeight::Log) - harmonic).abs() < 1e-7,
            "{}",
            value(ItemWeight::Log)
        );
        // Noise: weights (10, 100) / 55.
        let want = (0.1 * 10.0 / 55.0 + 0.001 * 100.0 / 55.0) / 2.0;
        assert!(
            (value(ItemWeight::Noise) - want).abs() < 1e-6,
            "{}",
            value(ItemWeight::Noise)
        );

        let x = errors(e, &device);
        let log = LossRule {
            distance: Distance::L1,
            weight: ItemWeight::Log,
        };
        let g = batch_loss(x.clone(), log, &levels, &clean).backward();
        let grad: Vec<f32> = x.grad(&g).unwrap().into_data().to_vec().unwrap();
        let n = 4 * 8 * 8;
        let (g0, g1) = (grad[0].abs() * n as f32, grad[n].abs() * n as f32);
        // d loss / d e_i = w_i / 2 / n with w = (10, 1000) / 505: w_i e_i equal.
        assert!((g0 * 0.1 - g1 * 0.001).abs() < 1e-4 * g0 * 0.1, "{g0} {g1}");
        assert!((g1 - 1000.0 / 1010.0).abs() < 1e-4, "{g1}");

        // MSE: plain mean of squares; log-weighted, the harmonic mean of the
        // items' MSEs (the gradient of the mean of ln MSE, i.e. of the mean
        // PSNR); noise-weighted by 1/sigma^2: weights (100, 10000) / 5050.
        let mse = |weight| -> f32 {
            let rule = LossRule {
                distance: Distance::Mse,
                weight,
            };
            batch_loss(errors(e, &device), rule, &levels, &clean).into_scalar()
        };
        let (m0, m1) = (0.1f32 * 0.1, 0.001f32 * 0.001);
        assert!((mse(ItemWeight::None) - (m0 + m1) / 2.0).abs() < 1e-8);
        let harmonic = 2.0 / (1.0 / m0 + 1.0 / m1);
        assert!((mse(ItemWeight::Log) - harmonic).abs() < 1e-3 * harmonic);
        let want = (m0 * 100.0 + m1 * 10_000.0) / 5050.0 / 2.0;
        assert!((mse(ItemWeight::Noise) - want).abs() < 1e-3 * want);
    }

    #[test]
    fn the_denoiser_learns() {
        let device = Default::default();
        let ((noisy, clean), mut net) = crate::seeded::seeded::<B, _>(&device, 7, || {
            (
                batch(&device),
                crate::seeded::materialise(SidUnetConfig::new().with_width(4).init::<B>(&device)),
            )
        });
        let mut optim = AdamConfig::new().init();
        let mut losses = Vec::new();
        for _ in 0..60 {
            let (n, l) = denoiser_step(net, &mut optim, noisy.clone(), clean.clone(), 3e-3);
            net = n;
            losses.push(l);
        }
        let (first, last) = (losses[0], *losses.last().unwrap());
        assert!(last < 0.5 * first, "loss {first} -> {last}");
    }

    #[test]
    fn the_flow_field_learns() {
        let device = Default::default();
        let ((noisy, clean), mut net, x0) = crate::seeded::seeded::<B, _>(&device, 11, || {
            let (noisy, clean) = batch(&device);
            let net = crate::seeded::materialise(
                Sr3Config::new()
                    .with_inner_channels(8)
                    .with_channel_mults(vec![1, 2])
                    .with_res_blocks(1)
                    .with_attn_levels(vec![])
                    .with_norm_groups(4)
                    .init::<B>(&device)
                    .unwrap(),
            );
            let x0 = Tensor::<B, 4>::random(clean.dims(), Distribution::Normal(0.0, 1.0), &device);
            ((noisy, clean), net, x0)
        });
        let mut optim = AdamConfig::new().init();
        let t = Tensor::<B, 1>::from_floats([0.3, 0.8], &device);
        let mut losses = Vec::new();
        for _ in 0..60 {
            let (n, l) = flow_step(
                net,
                &mut optim,
                noisy.clone(),
                clean.clone(),
                x0.clone(),
                t.clone(),
                3e-3,
            );
            net = n;
            losses.push(l);
        }
        let (first, last) = (losses[0], *losses.last().unwrap());
        assert!(last < 0.7 * first, "loss {first} -> {last}");
    }
}
