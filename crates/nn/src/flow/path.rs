//! The straight path of the rectified flow (paper eq. 4.1, 4.5):
//! Xt = t X1 + (1 - t) X0, from the start X0 ~ N(0, I) at t = 0 to the clean
//! image X1 at t = 1. Its velocity dXt/dt = X1 - X0 is constant along the
//! path; that is the target the network v(Xt, T, t) learns ([`super::loss`]).
//!
//! Training (Algorithm 1), the two-stage sampler's re-entry at t2
//! (eq. 4.11) and the sampling search (Algorithm 2) all go through
//! [`interpolate`].

use burn::tensor::backend::Backend;
use burn::tensor::Tensor;

/// Xt = t X1 + (1 - t) X0 (eq. 4.1, 4.5), with one time t per batch item.
///
/// - `x1`: X1, the end of the path: the clean image in training, the
///   first-stage estimate XZ in the two-stage sampler (eq. 4.11);
/// - `x0`: X0, the start: standard normal noise, same shape `(n, c, h, w)`;
/// - `t`: t in [0, 1], shape `(n)`.
///
/// Each element is `x1 * t + x0 * (1 - t)` in f32, `1 - t` rounded once, so
/// a batch of one with t = t2 gives the same bits as the scalar formula.
pub fn interpolate<B: Backend>(
    x1: Tensor<B, 4>,
    x0: Tensor<B, 4>,
    t: Tensor<B, 1>,
) -> Tensor<B, 4> {
    let n = t.dims()[0];
    let t4 = t.reshape([n, 1, 1, 1]);
    x1 * t4.clone() + x0 * (t4.neg() + 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::backend::Flex;
    use burn::tensor::{Distribution, Tensor};

    #[test]
    fn path_interpolation_endpoints() {
        let device = Default::default();
        let x1 = Tensor::<Flex, 4>::ones([2, 1, 2, 2], &device);
        let x0 = Tensor::<Flex, 4>::zeros([2, 1, 2, 2], &device);
        let xt = interpolate(x1, x0, Tensor::from_floats([0.0, 0.25], &device));
        let v: Vec<f32> = xt.into_data().to_vec().unwrap();
        assert_eq!(&v[..4], &[0.0; 4]);
        assert_eq!(&v[4..], &[0.25; 4]);
    }

    /// The per-item form gives the same bits as the scalar formula
    /// `x1 * t + x0 * (1 - t)` the samplers and the search used before
    /// they shared this function (outputs of `pgrf enhance` and `pgrf
    /// search` stay byte-identical).
    #[test]
    fn the_batched_time_matches_the_scalar_formula_bit_for_bit() {
        let device = Default::default();
        let x1 = Tensor::<Flex, 4>::random([1, 4, 8, 8], Distribution::Normal(0.3, 1.0), &device);
        let x0 = Tensor::<Flex, 4>::random([1, 4, 8, 8], Distribution::Normal(0.0, 1.0), &device);
        for t in [0.1f32, 0.3, 0.35, 0.6, 0.7, 0.9, 1.0, 0.123_456_7] {
            let scalar: Vec<f32> = (x1.clone() * t + x0.clone() * (1.0 - t))
                .into_data()
                .to_vec()
                .unwrap();
            let batched: Vec<f32> =
                interpolate(x1.clone(), x0.clone(), Tensor::from_floats([t], &device))
                    .into_data()
                    .to_vec()
                    .unwrap();
            let (a, b): (Vec<u32>, Vec<u32>) = (
                scalar.iter().map(|v| v.to_bits()).collect(),
                batched.iter().map(|v| v.to_bits()).collect(),
            );
            assert_eq!(a, b, "t = {t}");
        }
    }
}
