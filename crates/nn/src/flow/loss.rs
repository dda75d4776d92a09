//! The rectified-flow training objective (eq. 4.9, Algorithm 1's loss): the L1
//! distance between the network's velocity v(Xt, T, t) and the path's
//! constant velocity X1 - X0,
//!
//! ```text
//! L = | (X1 - X0) - v(Xt, T, t) |_1,  Xt = t X1 + (1 - t) X0 (eq. 4.1, 4.5),
//! ```
//!
//! averaged over pixels and batch items. T is the condition (the synthetic
//! noisy capture, amplified by its ratio), concatenated to the network's
//! input.

use super::path::interpolate;
use crate::arch::sr3::Sr3Unet;
use crate::loss::l1;
use crate::ops::PgrfOps;
use burn::tensor::Tensor;

/// The flow loss |X1 - X0 - v(Xt, T, t)|_1 at Xt = t X1 + (1 - t) X0.
///
/// - `net`: the velocity field v (SR3 U-Net);
/// - `cond`: T, the noisy condition, `(n, 4, h, w)`;
/// - `x1`: X1, the clean target; `x0`: X0 ~ N(0, I), same shape;
/// - `t`: t ~ U(0, 1), one per item, shape `(n)`.
///
/// X0 and t are drawn by the caller so that the training loop owns the
/// randomness and its seed. Returns the mean over every element, shape `(1)`.
pub fn flow_loss<B: PgrfOps>(
    net: &Sr3Unet<B>,
    cond: Tensor<B, 4>,
    x1: Tensor<B, 4>,
    x0: Tensor<B, 4>,
    t: Tensor<B, 1>,
) -> Tensor<B, 1> {
    let xt = interpolate(x1.clone(), x0.clone(), t.clone());
    l1(x1 - x0, net.forward(xt, cond, t))
}
