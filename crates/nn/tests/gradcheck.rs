//! Backward passes of the layers pgrf's networks run — the 3x3 convolution
//! (burn's and pgrf's own, `pgrf_nn::ops`), pgrf's transposed convolution,
//! LeakyReLU, SiLU and GroupNorm (the folded form in burn's operations and
//! pgrf's fused one) — against central finite differences of the same layer
//! on the plain backend. f32 arithmetic: steps of 1e-2 and a
//! tolerance of 2 % of the gradient's scale (conv is linear in its weights,
//! so there the difference quotient is exact up to rounding).

use burn::module::{AutodiffModule, Module};
use burn::nn::conv::Conv2dConfig;
use burn::nn::{GroupNormConfig, PaddingConfig2d};
use burn::tensor::backend::Backend;
use burn::tensor::{Distribution, Tensor, TensorData};
use pgrf_nn::backend::{Cpu, CpuTrain};
use pgrf_nn::named::{assign, collect};
use pgrf_nn::norm::group_norm;
use pgrf_nn::ops;
use pgrf_nn::seeded::seeded;

const H: f32 = 1e-2;

fn values<B: Backend, const D: usize>(t: Tensor<B, D>) -> Vec<f32> {
    t.into_data().convert::<f32>().to_vec().unwrap()
}

/// Compare analytic and numeric derivatives at a few indices.
fn check(what: &str, analytic: &[f32], numeric: impl Fn(usize) -> f32, picks: &[usize]) {
    let scale = analytic
        .iter()
        .fold(0.0f32, |m, v| m.max(v.abs()))
        .max(1e-3);
    for &i in picks {
        let n = numeric(i);
        let a = analytic[i];
        assert!(
            (a - n).abs() <= 0.02 * scale,
            "{what}[{i}]: autodiff {a}, finite difference {n} (scale {scale})"
        );
    }
}

/// Loss = sum(layer(x) * r), evaluated on the plain backend for finite differences.
fn loss_plain<M: Module<Cpu>>(
    m: &M,
    fwd: impl Fn(&M, Tensor<Cpu, 4>) -> Tensor<Cpu, 4>,
    x: &[f32],
    shape: [usize; 4],
    r: &Tensor<Cpu, 4>,
) -> f32 {
    let xt = Tensor::<Cpu, 4>::from_data(TensorData::new(x.to_vec(), shape), &Default::default());
    values((fwd(m, xt) * r.clone()).sum())[0]
}

#[test]
fn conv3x3_gradients_match_finite_differences() {
    conv3x3_case(false);
}

#[test]
fn pgrf_conv3x3_gradients_match_finite_differences() {
    conv3x3_case(true);
}

/// burn's convolution (`pgrf` false) or pgrf's.
fn conv3x3_case(pgrf: bool) {
    let device = Default::default();
    let shape = [2, 3, 7, 6];
    let cfg = Conv2dConfig::new([3, 4], [3, 3]).with_padding(PaddingConfig2d::Same);
    let (conv, x, out, r) = seeded::<CpuTrain, _>(&device, 3, || {
        let conv = cfg.init::<CpuTrain>(&device);
        let x = Tensor::<CpuTrain, 4>::random(shape, Distribution::Normal(0.0, 1.0), &device)
            .require_grad();
        let out = if pgrf {
            ops::conv2d(&conv, x.clone())
        } else {
            conv.forward(x.clone())
        };
        let r = Tensor::<CpuTrain, 4>::random(out.dims(), Distribution::Normal(0.0, 1.0), &device);
        (conv, x, out, r)
    });
    let grads = (out * r.clone()).sum().backward();
    let gw = values(conv.weight.val().grad(&grads).unwrap());
    let gb = values(conv.bias.as_ref().unwrap().val().grad(&grads).unwrap());
    let gx = values(x.grad(&grads).unwrap());

    let plain = conv.valid();
    let r = r.inner();
    let xv = values(x.inner());
    let named = collect::<Cpu, _>(&plain);
    let fwd = |m: &burn::nn::conv::Conv2d<Cpu>, x| {
        if pgrf {
            ops::conv2d(m, x)
        } else {
            m.forward(x)
        }
    };
    let perturbed = |name: &str, i: usize, d: f32| {
        let mut n = named.clone();
        n.get_mut(name).unwrap().values[i] += d;
        let m = assign(cfg.init::<Cpu>(&device), &n, &device).unwrap();
        loss_plain(&m, fwd, &xv, shape, &r)
    };
    check(
        "weight",
        &gw,
        |i| (perturbed("weight", i, H) - perturbed("weight", i, -H)) / (2.0 * H),
        &[0, 17, 50, 107],
    );
    check(
        "bias",
        &gb,
        |i| (perturbed("bias", i, H) - perturbed("bias", i, -H)) / (2.0 * H),
        &[0, 3],
    );
    let in_x = |i: usize, d: f32| {
        let mut xs = xv.clone();
        xs[i] += d;
        loss_plain(&plain, fwd, &xs, shape, &r)
    };
    // Corners and interior pixels: padding must be differentiated correctly too.
    check(
        "input",
        &gx,
        |i| (in_x(i, H) - in_x(i, -H)) / (2.0 * H),
        &[0, 5, 41, 126, 251],
    );
}

#[test]
fn group_norm_gradients_match_finite_differences() {
    let device = Default::default();
    let shape = [2, 8, 5, 4];
    let cfg = GroupNormConfig::new(4, 8);
    let gn = cfg.init::<CpuTrain>(&device);
    // Non-trivial affine parameters, so their gradients are exercised away from 1 and 0.
    let mut named = collect::<CpuTrain, _>(&gn);
    for (k, t) in named.iter_mut() {
        for (i, v) in t.values.iter_mut().enumerate() {
            *v = if k.ends_with("gamma") {
                0.5 + 0.1 * i as f32
            } else {
                -0.2 + 0.05 * i as f32
            };
        }
    }
    let gn = assign(gn, &named, &device).unwrap();
    let (x, out, r) = seeded::<CpuTrain, _>(&device, 4, || {
        let x = Tensor::<CpuTrain, 4>::random(shape, Distribution::Normal(0.3, 2.0), &device)
            .require_grad();
        let out = group_norm(&gn, x.clone());
        let r = Tensor::<CpuTrain, 4>::random(out.dims(), Distribution::Normal(0.0, 1.0), &device);
        (x, out, r)
    });
    let grads = (out * r.clone()).sum().backward();
    let gg = values(gn.gamma.as_ref().unwrap().val().grad(&grads).unwrap());
    let gx = values(x.grad(&grads).unwrap());

    let plain = gn.valid();
    let r = r.inner();
    let xv = values(x.inner());
    let fwd = |m: &burn::nn::GroupNorm<Cpu>, x| group_norm(m, x);
    let pnamed = collect::<Cpu, _>(&plain);
    let gamma = |i: usize, d: f32| {
        let mut n = pnamed.clone();
        n.get_mut("gamma").unwrap().values[i] += d;
        let m = assign(cfg.init::<Cpu>(&device), &n, &device).unwrap();
        loss_plain(&m, fwd, &xv, shape, &r)
    };
    check(
        "gamma",
        &gg,
        |i| (gamma(i, H) - gamma(i, -H)) / (2.0 * H),
        &[0, 3, 7],
    );
    let in_x = |i: usize, d: f32| {
        let mut xs = xv.clone();
        xs[i] += d;
        loss_plain(&plain, fwd, &xs, shape, &r)
    };
    check(
        "input",
        &gx,
        |i| (in_x(i, H) - in_x(i, -H)) / (2.0 * H),
        &[0, 19, 77, 160, 319],
    );
}

/// Input gradient of `layer` (the same function on both backends) against
/// central differences at `picks`.
fn input_gradient_case(
    what: &str,
    shape: [usize; 4],
    seed: u64,
    train: impl Fn(Tensor<CpuTrain, 4>) -> Tensor<CpuTrain, 4>,
    plain: impl Fn(Tensor<Cpu, 4>) -> Tensor<Cpu, 4>,
    picks: &[usize],
) {
    let device = Default::default();
    let (x, r) = seeded::<CpuTrain, _>(&device, seed, || {
        let x = Tensor::<CpuTrain, 4>::random(shape, Distribution::Normal(0.0, 2.0), &device)
            .require_grad();
        let r = Tensor::<CpuTrain, 4>::random(
            train(x.clone()).dims(),
            Distribution::Normal(0.0, 1.0),
            &device,
        );
        (x, r)
    });
    let grads = (train(x.clone()) * r.clone()).sum().backward();
    let gx = values(x.grad(&grads).unwrap());
    let (xv, r) = (values(x.inner()), r.inner());
    let at = |i: usize, d: f32| {
        let mut xs = xv.clone();
        xs[i] += d;
        let xt = Tensor::<Cpu, 4>::from_data(TensorData::new(xs, shape), &device);
        values((plain(xt) * r.clone()).sum())[0]
    };
    // Points within H of LeakyReLU's kink would compare a one-sided slope.
    let picks: Vec<usize> = picks
        .iter()
        .copied()
        .filter(|&i| xv[i].abs() > 2.0 * H)
        .collect();
    assert!(picks.len() >= 3, "{what}: too few usable points");
    check(what, &gx, |i| (at(i, H) - at(i, -H)) / (2.0 * H), &picks);
}

#[test]
fn pgrf_activations_and_norm_gradients_match_finite_differences() {
    let picks = [0, 11, 37, 64, 101, 150, 199];
    input_gradient_case(
        "leaky relu",
        [2, 4, 5, 5],
        21,
        |x| ops::leaky_relu(x, 0.2),
        |x| ops::leaky_relu(x, 0.2),
        &picks,
    );
    input_gradient_case("silu", [2, 4, 5, 5], 22, ops::silu, ops::silu, &picks);
    let device = Default::default();
    let gn = GroupNormConfig::new(2, 4).init::<CpuTrain>(&device);
    let mut named = collect::<CpuTrain, _>(&gn);
    for (k, t) in named.iter_mut() {
        for (i, v) in t.values.iter_mut().enumerate() {
            *v = if k.ends_with("gamma") {
                0.7 + 0.2 * i as f32
            } else {
                0.1 * i as f32
            };
        }
    }
    let gn = assign(gn, &named, &device).unwrap();
    let plain = gn.valid();
    input_gradient_case(
        "pgrf group norm",
        [2, 4, 5, 5],
        23,
        |x| ops::group_norm(&gn, x),
        |x| ops::group_norm(&plain, x),
        &picks,
    );
}

#[test]
fn pgrf_transposed_convolution_gradient_matches_finite_differences() {
    let device = Default::default();
    let up = seeded::<CpuTrain, _>(&device, 24, || {
        burn::nn::conv::ConvTranspose2dConfig::new([3, 2], [2, 2])
            .with_stride([2, 2])
            .init::<CpuTrain>(&device)
    });
    let plain = up.valid();
    input_gradient_case(
        "pgrf transposed conv",
        [2, 3, 4, 5],
        25,
        |x| ops::conv_transpose2d(&up, x),
        |x| ops::conv_transpose2d(&plain, x),
        &[0, 9, 33, 58, 77, 101, 119],
    );
}
