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
use crate::ops::{PgrfAutodiff, PgrfOps};
use burn::optim::{GradientsParams, Optimizer};
use burn::tensor::{ElementConversion, Tensor};

/// Mean absolute error over every element.
pub(crate) fn l1<B: PgrfOps>(a: Tensor<B, 4>, b: Tensor<B, 4>) -> Tensor<B, 1> {
    (a - b).abs().mean()
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
