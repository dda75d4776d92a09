//! Samplers of the rectified flow. The paper's point is two network
//! evaluations instead of hundreds: XZ = v(X0, T, 0) + X0 jumps straight to
//! a first estimate, Xt2 = t2 XZ + (1 - t2) X0 re-enters the path at the
//! searched time t2, and XM = v(Xt2, T, t2) + X0 is the result (eq. 4.10-4.12).
//! Euler integration is kept for comparison.

use crate::sr3::Sr3Unet;
use burn::tensor::backend::Backend;
use burn::tensor::Tensor;

fn times<B: Backend>(n: usize, t: f32, device: &B::Device) -> Tensor<B, 1> {
    Tensor::<B, 1>::full([n], t, device)
}

/// The two-stage sampler with second time `t2`.
pub fn two_stage<B: Backend>(
    net: &Sr3Unet<B>,
    cond: Tensor<B, 4>,
    x0: Tensor<B, 4>,
    t2: f32,
) -> Tensor<B, 4> {
    let n = x0.dims()[0];
    let device = x0.device();
    let xz = net.forward(x0.clone(), cond.clone(), times::<B>(n, 0.0, &device)) + x0.clone();
    let xt2 = xz * t2 + x0.clone() * (1.0 - t2);
    net.forward(xt2, cond, times::<B>(n, t2, &device)) + x0
}

/// One network evaluation: X0 + v(X0, T, 0).
pub fn one_step<B: Backend>(
    net: &Sr3Unet<B>,
    cond: Tensor<B, 4>,
    x0: Tensor<B, 4>,
) -> Tensor<B, 4> {
    let n = x0.dims()[0];
    let device = x0.device();
    net.forward(x0.clone(), cond, times::<B>(n, 0.0, &device)) + x0
}

/// Euler integration of dX/dt = v(X, T, t) from t = 0 to 1 in `steps` steps.
pub fn euler<B: Backend>(
    net: &Sr3Unet<B>,
    cond: Tensor<B, 4>,
    x0: Tensor<B, 4>,
    steps: usize,
) -> Tensor<B, 4> {
    let n = x0.dims()[0];
    let device = x0.device();
    let dt = 1.0 / steps.max(1) as f32;
    let mut x = x0;
    for i in 0..steps.max(1) {
        let v = net.forward(
            x.clone(),
            cond.clone(),
            times::<B>(n, i as f32 * dt, &device),
        );
        x = x + v * dt;
    }
    x
}
