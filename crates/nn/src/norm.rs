//! GroupNorm written for the layouts burn's Flex backend is fast at.
//!
//! burn's `GroupNorm` applies its affine as `x * gamma.reshape([1, c, 1, 1])`,
//! a broadcast Flex walks element by element; in SR3 that made GroupNorm 39 %
//! of the forward pass (BENCHMARKS.md, issue 5). Here the statistics are taken
//! on `(n, g, c/g * h * w)` and the affine is folded with 1/std into one scale
//! and one shift per (n, c) row of an `(n * c, h * w)` view, so every
//! full-size operation is same-shape or per-row. Same parameters, same
//! numbers (biased variance, epsilon inside the root) as `burn::nn::GroupNorm`.

use burn::nn::GroupNorm;
use burn::tensor::backend::Backend;
use burn::tensor::Tensor;

/// `norm` (burn's `GroupNorm`: its group count, epsilon and optional affine)
/// applied to `x`, `(n, c, h, w)` with `c` a multiple of the group count;
/// returns the same shape. Equal to `norm.forward(x)` to rounding, faster on
/// Flex; SR3 ([`crate::arch::sr3`]) runs every GroupNorm through it.
pub fn group_norm<B: Backend>(norm: &GroupNorm<B>, x: Tensor<B, 4>) -> Tensor<B, 4> {
    folded(
        x,
        norm.gamma.as_ref().map(|g| g.val()),
        norm.beta.as_ref().map(|b| b.val()),
        norm.num_groups,
        norm.epsilon,
    )
}

/// [`group_norm`] from its parts: `groups` groups, `epsilon`, the optional
/// per-channel scale `gamma` and shift `beta` (both or neither).
pub(crate) fn folded<B: Backend>(
    x: Tensor<B, 4>,
    gamma: Option<Tensor<B, 1>>,
    beta: Option<Tensor<B, 1>>,
    groups: usize,
    epsilon: f64,
) -> Tensor<B, 4> {
    let [n, c, h, w] = x.dims();
    let g = groups;
    let cg = c / g;
    let grouped = x.reshape([n, g, cg * h * w]);
    let mean = grouped.clone().mean_dim(2);
    let centred = grouped - mean;
    let var = centred.clone().square().mean_dim(2);
    let rstd = var.add_scalar(epsilon).sqrt().recip(); // (n, g, 1)
    let (Some(gamma), Some(beta)) = (gamma, beta) else {
        return (centred * rstd).reshape([n, c, h, w]);
    };
    let rows = centred.reshape([n * c, h * w]);
    let scale = (rstd * gamma.reshape([1, g, cg])).reshape([n * c, 1]);
    let shift = beta.reshape([1, c]).expand([n, c]).reshape([n * c, 1]);
    (rows * scale + shift).reshape([n, c, h, w])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::Cpu;
    use crate::named::{assign, collect};
    use burn::nn::GroupNormConfig;
    use burn::tensor::Distribution;

    #[test]
    fn equals_burns_group_norm() {
        let device = Default::default();
        let gn = GroupNormConfig::new(4, 16).init::<Cpu>(&device);
        let mut named = collect::<Cpu, _>(&gn);
        for t in named.values_mut() {
            for (i, v) in t.values.iter_mut().enumerate() {
                *v += 0.1 * i as f32 - 0.4;
            }
        }
        let gn = assign(gn, &named, &device).unwrap();
        let x = Tensor::<Cpu, 4>::random([3, 16, 5, 7], Distribution::Normal(0.5, 2.0), &device);
        let d: f32 = (group_norm(&gn, x.clone()) - gn.forward(x))
            .abs()
            .max()
            .into_scalar();
        assert!(d < 1e-5, "{d}");
    }
}
