//! `pgrf-bench train --breakdown`: where a training step's time goes.
//!
//! The layers come from the network itself (`SidUnet::layers`,
//! `Sr3Unet::layers` in pgrf-nn, read from the built modules), so this file
//! restates no architecture. Each distinct layer shape is built fresh and
//! timed alone: forward on the inference backend, forward and backward
//! through autodiff (the backward of `sum()`, a gradient of ones), the three
//! backend calls of a convolution's backward, and the alternatives measured
//! against burn's own layers (im2col + matmul convolutions, pgrf's folded
//! GroupNorm, burn's fused attention). Times are summed per layer kind.

use super::{sync, time_it, uniform};
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use burn::nn::{
    GroupNorm, GroupNormConfig, LeakyRelu, LeakyReluConfig, Linear, LinearConfig, PaddingConfig2d,
};
use burn::tensor::backend::Backend;
use burn::tensor::ops::{AttentionModuleOptions, ConvOptions, ModuleOps, PadMode};
use burn::tensor::{Distribution, Tensor, TensorData};
use pgrf_core::stats::median;
use pgrf_nn::arch::sr3::attention_core;
use pgrf_nn::backend::{Cpu, CpuTrain};
use pgrf_nn::layers::Layer;
use pgrf_nn::norm::group_norm;
use pgrf_nn::ops::{self, PgrfOps};
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Instant;

/// One layer to time: its shape, and whether its input needs a gradient
/// (false only for the network's first convolution, whose input is data).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct Op {
    layer: Layer,
    grad_x: bool,
}

impl Op {
    /// The network's layers, the first convolution marked as reading data.
    fn list(layers: &[Layer]) -> Vec<Op> {
        let first_conv = layers.iter().position(|l| matches!(l, Layer::Conv { .. }));
        layers
            .iter()
            .enumerate()
            .map(|(i, &layer)| Op {
                layer,
                grad_x: Some(i) != first_conv,
            })
            .collect()
    }

    /// The row of the table this layer is summed into.
    fn kind(&self) -> String {
        match self.layer {
            Layer::Conv { kernel, stride, .. } => {
                let mut k = format!("conv {kernel}x{kernel}");
                if stride > 1 {
                    k += &format!(" stride {stride}");
                }
                k
            }
            Layer::ConvTranspose { kernel, .. } => format!("conv transpose {kernel}x{kernel}"),
            Layer::GroupNorm { .. } => "group norm".into(),
            Layer::LeakyRelu { .. } => "leaky relu".into(),
            Layer::Silu { .. } => "silu".into(),
            Layer::Attention { .. } => "attention core".into(),
            Layer::Linear { .. } => "linear".into(),
        }
    }

    /// The layer's input for a batch of `n` (a linear layer's vectors as
    /// `(n, 1, 1, d_in)`; the attention core's is the qkv projection).
    fn input_shape(&self, n: usize) -> [usize; 4] {
        match self.layer {
            Layer::Conv { cin, h, w, .. } | Layer::ConvTranspose { cin, h, w, .. } => {
                [n, cin, h, w]
            }
            Layer::GroupNorm { channels, h, w, .. }
            | Layer::LeakyRelu { channels, h, w }
            | Layer::Silu { channels, h, w } => [n, channels, h, w],
            Layer::Attention { channels, h, w } => [n, 3 * channels, h, w],
            Layer::Linear { d_in, .. } => [n, 1, 1, d_in],
        }
    }
}

/// A layer of that shape built on backend `B` (fresh weights: the cost does
/// not depend on their values).
enum Built<B: Backend> {
    Conv(Conv2d<B>),
    ConvT(ConvTranspose2d<B>),
    Norm(GroupNorm<B>),
    LeakyRelu(LeakyRelu),
    Silu,
    Attention(usize),
    Linear(Linear<B>),
}

impl<B: Backend> Built<B> {
    fn new(layer: &Layer, device: &B::Device) -> Self {
        match *layer {
            Layer::Conv {
                cin,
                cout,
                kernel,
                stride,
                padding: p,
                ..
            } => Built::Conv(
                Conv2dConfig::new([cin, cout], [kernel, kernel])
                    .with_stride([stride, stride])
                    .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
                    .init(device),
            ),
            Layer::ConvTranspose {
                cin,
                cout,
                kernel,
                stride,
                ..
            } => Built::ConvT(
                ConvTranspose2dConfig::new([cin, cout], [kernel, kernel])
                    .with_stride([stride, stride])
                    .init(device),
            ),
            Layer::GroupNorm {
                channels, groups, ..
            } => Built::Norm(GroupNormConfig::new(groups, channels).init(device)),
            // The slope does not change the cost.
            Layer::LeakyRelu { .. } => Built::LeakyRelu(LeakyReluConfig::new().init()),
            Layer::Silu { .. } => Built::Silu,
            Layer::Attention { channels, .. } => Built::Attention(channels),
            Layer::Linear { d_in, d_out } => {
                Built::Linear(LinearConfig::new(d_in, d_out).init(device))
            }
        }
    }
}

impl<B: PgrfOps> Built<B> {
    /// The layer as the networks run it: through pgrf's operations unless
    /// `--kernels burn` chose burn's.
    fn forward(&self, x: Tensor<B, 4>) -> Tensor<B, 4> {
        match self {
            Built::Conv(m) => ops::conv2d(m, x),
            Built::ConvT(m) => ops::conv_transpose2d(m, x),
            Built::Norm(m) => ops::group_norm(m, x),
            Built::LeakyRelu(m) => ops::leaky_relu(x, m.negative_slope as f32),
            Built::Silu => ops::silu(x),
            Built::Attention(c) => {
                let [n, _, h, w] = x.dims();
                attention_core(x.reshape([n, 3 * c, h * w]), *c).reshape([n, *c, h, w])
            }
            Built::Linear(m) => m.forward(x),
        }
    }
}

/// The same attention core through burn's fused `module::attention` (Flex
/// has a native kernel; under autodiff burn 0.21 falls back to separate ops).
fn attention_fused<B: Backend>(qkv: Tensor<B, 3>, c: usize) -> Tensor<B, 3> {
    let [n, _, hw] = qkv.dims();
    let qkv = qkv.swap_dims(1, 2); // (n, hw, 3c)
    let part = |i: usize| {
        qkv.clone()
            .slice([0..n, 0..hw, i * c..(i + 1) * c])
            .reshape([n, 1, hw, c])
    };
    let out = burn::tensor::module::attention(
        part(0),
        part(1),
        part(2),
        None,
        None,
        AttentionModuleOptions {
            scale: None,
            softcap: None,
            is_causal: false,
        },
    );
    out.reshape([n, hw, c]).swap_dims(1, 2)
}

/// (inference forward, autodiff forward + backward) of pgrf's folded
/// GroupNorm (`pgrf_nn::norm::group_norm`, what SR3 runs) at the shape of
/// `op`, ms.
fn time_gn_folded(op: &Op, n: usize, reps: usize) -> (f64, f64) {
    let Layer::GroupNorm {
        channels,
        groups,
        h,
        w,
    } = op.layer
    else {
        return (0.0, 0.0);
    };
    let device = Default::default();
    let m = GroupNormConfig::new(groups, channels).init::<Cpu>(&device);
    let x = uniform::<Cpu>([n, channels, h, w], &device);
    let fwd = time_it(1, reps, || {
        std::hint::black_box(group_norm(&m, x.clone()));
    })
    .0;
    let m = GroupNormConfig::new(groups, channels).init::<CpuTrain>(&device);
    let mut ts = Vec::new();
    for i in 0..reps + 1 {
        let x = uniform::<CpuTrain>([n, channels, h, w], &device).require_grad();
        let t0 = Instant::now();
        let grads = group_norm(&m, x).sum().backward();
        sync::<CpuTrain>(&device);
        std::hint::black_box(grads);
        if i > 0 {
            ts.push(t0.elapsed().as_secs_f64() * 1e3);
        }
    }
    (fwd, median(&mut ts))
}

/// Inference forward of `op`, ms.
fn time_forward(op: &Op, n: usize, reps: usize) -> f64 {
    let device = Default::default();
    let layer = Built::<Cpu>::new(&op.layer, &device);
    let x = uniform::<Cpu>(op.input_shape(n), &device);
    time_it(1, reps, || {
        std::hint::black_box(layer.forward(x.clone()));
        sync::<Cpu>(&device);
    })
    .0
}

/// (autodiff forward, backward) of `op`, ms.
fn time_train(op: &Op, n: usize, reps: usize) -> (f64, f64) {
    let device = Default::default();
    let layer = Built::<CpuTrain>::new(&op.layer, &device);
    let (mut fwd, mut bwd) = (Vec::new(), Vec::new());
    for i in 0..reps + 1 {
        let x = uniform::<CpuTrain>(op.input_shape(n), &device);
        let x = if op.grad_x { x.require_grad() } else { x };
        let t0 = Instant::now();
        let y = layer.forward(x);
        sync::<CpuTrain>(&device);
        let t1 = Instant::now();
        // Summing is a cheap stand-in for the rest of the network: its
        // backward hands the layer a gradient of ones.
        let s = y.sum();
        let t2 = Instant::now();
        let grads = s.backward();
        sync::<CpuTrain>(&device);
        let t3 = Instant::now();
        std::hint::black_box(grads);
        if i > 0 {
            fwd.push((t1 - t0).as_secs_f64() * 1e3);
            bwd.push((t3 - t2).as_secs_f64() * 1e3);
        }
    }
    (median(&mut fwd), median(&mut bwd))
}

/// Backend-level backward of one convolution on Flex, the three calls burn's
/// autodiff makes: (x gradient, weight gradient, bias gradient), ms.
fn time_conv_grads(op: &Op, n: usize, reps: usize) -> (f64, f64, f64) {
    let Layer::Conv {
        cin,
        cout,
        kernel: k,
        stride,
        padding: p,
        h,
        w,
    } = op.layer
    else {
        return (0.0, 0.0, 0.0);
    };
    let device = Default::default();
    let options = ConvOptions::new([stride, stride], [p, p], [1, 1], 1);
    let (ho, wo) = ((h + 2 * p - k) / stride + 1, (w + 2 * p - k) / stride + 1);
    let prim = |t: Tensor<Cpu, 4>| t.into_primitive().tensor();
    let x = prim(uniform::<Cpu>([n, cin, h, w], &device));
    let weight = prim(uniform::<Cpu>([cout, cin, k, k], &device));
    let g = prim(uniform::<Cpu>([n, cout, ho, wo], &device));
    let bias = Tensor::<Cpu, 1>::zeros([cout], &device)
        .into_primitive()
        .tensor();
    let xg = if op.grad_x {
        time_it(1, reps, || {
            std::hint::black_box(Cpu::conv2d_x_backward(
                x.clone(),
                weight.clone(),
                g.clone(),
                options.clone(),
            ));
        })
        .0
    } else {
        0.0
    };
    let wg = time_it(1, reps, || {
        std::hint::black_box(Cpu::conv2d_weight_backward(
            x.clone(),
            weight.clone(),
            g.clone(),
            options.clone(),
        ));
    })
    .0;
    let bg = time_it(1, reps, || {
        std::hint::black_box(Cpu::conv2d_bias_backward(
            x.clone(),
            bias.clone(),
            g.clone(),
        ));
    })
    .0;
    (xg, wg, bg)
}

/// A stride-1 k x k convolution with padding k / 2 written with tensor ops
/// only (zero pad, k*k shifted views concatenated = im2col, one batched
/// matmul), so that autodiff derives its backward from matmul, slice and
/// pad: `w` is `(1, cout, cin*k*k)`, `b` is `(1, cout, 1)`.
fn conv_im2col<B: Backend>(
    x: Tensor<B, 4>,
    w: Tensor<B, 3>,
    b: Tensor<B, 3>,
    k: usize,
) -> Tensor<B, 4> {
    let [n, cin, h, wd] = x.dims();
    let cout = w.dims()[1];
    let cols = if k == 1 {
        x.reshape([n, cin, h * wd])
    } else {
        let p = k / 2;
        let xp = x.pad((p, p, p, p), PadMode::Constant(0.0));
        let mut taps = Vec::with_capacity(k * k);
        for kh in 0..k {
            for kw in 0..k {
                taps.push(
                    xp.clone()
                        .slice([0..n, 0..cin, kh..kh + h, kw..kw + wd])
                        .unsqueeze_dim::<5>(2),
                );
            }
        }
        Tensor::cat(taps, 2).reshape([n, cin * k * k, h * wd])
    };
    (w.matmul(cols) + b).reshape([n, cout, h, wd])
}

/// (inference forward, autodiff forward + backward) of `conv_im2col` at the
/// shape of `op`, ms; None unless `op` is a stride-1 convolution padded by
/// half its odd kernel (the shape-preserving ones `conv_im2col` writes).
fn time_im2col(op: &Op, n: usize, reps: usize) -> Option<(f64, f64)> {
    let Layer::Conv {
        cin,
        cout,
        kernel: k,
        stride: 1,
        padding,
        h,
        w,
    } = op.layer
    else {
        return None;
    };
    if k % 2 == 0 || padding != k / 2 {
        return None;
    }
    let kk = cin * k * k;
    let device = Default::default();
    let wi = Tensor::<Cpu, 3>::random([1, cout, kk], Distribution::Uniform(-0.1, 0.1), &device);
    let bi = Tensor::<Cpu, 3>::zeros([1, cout, 1], &device);
    let xi = uniform::<Cpu>([n, cin, h, w], &device);
    let fwd = time_it(1, reps, || {
        std::hint::black_box(conv_im2col(xi.clone(), wi.clone(), bi.clone(), k));
    })
    .0;
    let wt =
        Tensor::<CpuTrain, 3>::random([1, cout, kk], Distribution::Uniform(-0.1, 0.1), &device)
            .require_grad();
    let bt = Tensor::<CpuTrain, 3>::zeros([1, cout, 1], &device).require_grad();
    let mut ts = Vec::new();
    for i in 0..reps + 1 {
        let x = uniform::<CpuTrain>([n, cin, h, w], &device);
        let x = if op.grad_x { x.require_grad() } else { x };
        let t0 = Instant::now();
        let grads = conv_im2col(x, wt.clone(), bt.clone(), k).sum().backward();
        sync::<CpuTrain>(&device);
        std::hint::black_box(grads);
        if i > 0 {
            ts.push(t0.elapsed().as_secs_f64() * 1e3);
        }
    }
    Some((fwd, median(&mut ts)))
}

/// The network's GroupNorm layers: burn's `GroupNorm` against pgrf's
/// folded one, summed, ms.
#[derive(Serialize, Default)]
struct NormDetail {
    layers: usize,
    burn_forward_ms: f64,
    folded_forward_ms: f64,
    burn_train_ms: f64,
    folded_train_ms: f64,
}

/// Where the convolutions' time goes, summed over the network's layers.
#[derive(Serialize, Default)]
struct ConvDetail {
    /// Flex's conv2d backward, split into the three calls autodiff makes
    /// (convolutions; transposed convolutions not included), ms.
    x_grad_ms: f64,
    weight_grad_ms: f64,
    bias_grad_ms: f64,
    /// Stride-1 convolutions only: burn's Conv2d against the same
    /// convolution as im2col + matmul in tensor ops (`conv_im2col`), ms.
    stride1_layers: usize,
    conv2d_forward_ms: f64,
    im2col_forward_ms: f64,
    conv2d_train_ms: f64,
    im2col_train_ms: f64,
    /// The 1x1 convolutions among them (im2col is a plain reshape there, so
    /// the alternative is one matmul), forward + backward, ms.
    pointwise_layers: usize,
    pointwise_conv2d_train_ms: f64,
    pointwise_matmul_train_ms: f64,
}

/// One layer kind, summed over the network's layers of that kind, ms.
#[derive(Serialize)]
struct KindTime {
    kind: String,
    layers: usize,
    forward_ms: f64,
    forward_train_ms: f64,
    backward_ms: f64,
}

/// The breakdown of one network's step (part of `pgrf-bench train --json`).
#[derive(Serialize)]
pub(super) struct Breakdown {
    /// Real network, median over a few steps: forward (with loss), backward,
    /// optimiser (gradient collection + Adam update), ms.
    step_forward_ms: f64,
    step_backward_ms: f64,
    step_optimizer_ms: f64,
    /// Per layer kind, summed over the network's layers, each timed alone.
    kinds: Vec<KindTime>,
    /// Inference forward not covered by the timed layers (pooling,
    /// concatenation, padding, interpolation, adds), ms.
    forward_other_ms: f64,
    /// Training step not covered by the timed layers nor the optimiser, ms.
    step_other_ms: f64,
    /// Host -> tensor upload of one step's inputs, ms.
    data_upload_ms: f64,
    /// Attention core on the inference backend through burn's fused
    /// `module::attention`, summed over the network's attention layers, ms.
    #[serde(skip_serializing_if = "Option::is_none")]
    attention_fused_forward_ms: Option<f64>,
    conv: ConvDetail,
    /// GroupNorm layers: burn's `GroupNorm` against `pgrf_nn::norm::group_norm`,
    /// inference forward and autodiff forward + backward, ms.
    #[serde(skip_serializing_if = "Option::is_none")]
    group_norm_folded: Option<NormDetail>,
    forward_total_ms: f64,
    /// The step's median from the main timing loop, ms.
    train_step_ms: f64,
    /// Sum of the split above (percentages are of this), ms.
    split_total_ms: f64,
}

/// Time every distinct layer of `layers` (a batch of `n`, input side
/// `side`) and put the sums beside the real step's `split` (forward,
/// backward, optimiser per step, ms); `input_planes`: the step's input
/// tensors, for the upload time.
pub(super) fn breakdown(
    n: usize,
    side: usize,
    split: Vec<[f64; 3]>,
    layers: &[Layer],
    forward_total_ms: f64,
    train_step_ms: f64,
    input_planes: usize,
) -> Breakdown {
    let reps = 3;
    let mut counts: BTreeMap<Op, usize> = BTreeMap::new();
    for op in Op::list(layers) {
        *counts.entry(op).or_default() += 1;
    }
    let mut kinds: BTreeMap<String, KindTime> = BTreeMap::new();
    let mut fused = None;
    let mut conv = ConvDetail::default();
    let mut norm: Option<NormDetail> = None;
    for (op, &count) in &counts {
        let f = time_forward(op, n, reps);
        let (ft, b) = time_train(op, n, reps);
        let c = count as f64;
        if let Layer::GroupNorm { .. } = op.layer {
            let (ff, ft2) = time_gn_folded(op, n, reps);
            let d = norm.get_or_insert_with(NormDetail::default);
            d.layers += count;
            d.burn_forward_ms += f * c;
            d.folded_forward_ms += ff * c;
            d.burn_train_ms += (ft + b) * c;
            d.folded_train_ms += ft2 * c;
        }
        if let Layer::Conv { kernel, .. } = op.layer {
            let (xg, wg, bg) = time_conv_grads(op, n, reps);
            conv.x_grad_ms += xg * c;
            conv.weight_grad_ms += wg * c;
            conv.bias_grad_ms += bg * c;
            if let Some((af, at)) = time_im2col(op, n, reps) {
                conv.stride1_layers += count;
                conv.conv2d_forward_ms += f * c;
                conv.im2col_forward_ms += af * c;
                conv.conv2d_train_ms += (ft + b) * c;
                conv.im2col_train_ms += at * c;
                if kernel == 1 {
                    conv.pointwise_layers += count;
                    conv.pointwise_conv2d_train_ms += (ft + b) * c;
                    conv.pointwise_matmul_train_ms += at * c;
                }
            }
        }
        let kind = op.kind();
        let k = kinds.entry(kind.clone()).or_insert(KindTime {
            kind,
            layers: 0,
            forward_ms: 0.0,
            forward_train_ms: 0.0,
            backward_ms: 0.0,
        });
        k.layers += count;
        k.forward_ms += f * c;
        k.forward_train_ms += ft * c;
        k.backward_ms += b * c;
        if let Layer::Attention { channels, h, w } = op.layer {
            let device = Default::default();
            let qkv =
                uniform::<Cpu>([n, 3 * channels, h, w], &device).reshape([n, 3 * channels, h * w]);
            let (ms, _) = time_it(1, reps, || {
                std::hint::black_box(attention_fused(qkv.clone(), channels));
            });
            *fused.get_or_insert(0.0) += ms * c;
        }
    }
    let kinds: Vec<KindTime> = kinds.into_values().collect();
    let col = |i: usize| {
        let mut v: Vec<f64> = split.iter().map(|s| s[i]).collect();
        median(&mut v)
    };
    let (sf, sb, so) = (col(0), col(1), col(2));
    let layer_fwd: f64 = kinds.iter().map(|k| k.forward_ms).sum();
    let layer_train: f64 = kinds
        .iter()
        .map(|k| k.forward_train_ms + k.backward_ms)
        .sum();
    // Data: the step's input planes as host vectors, uploaded.
    let device = Default::default();
    let host: Vec<Vec<f32>> = (0..input_planes)
        .map(|p| {
            (0..n * 4 * side * side)
                .map(|i| ((i + p) % 97) as f32 / 97.0)
                .collect()
        })
        .collect();
    let (data_upload_ms, _) = time_it(1, 5, || {
        for h in &host {
            let t = Tensor::<CpuTrain, 4>::from_data(
                TensorData::new(h.clone(), [n, 4, side, side]),
                &device,
            );
            std::hint::black_box(t);
        }
    });
    Breakdown {
        step_forward_ms: sf,
        step_backward_ms: sb,
        step_optimizer_ms: so,
        kinds,
        forward_other_ms: forward_total_ms - layer_fwd,
        step_other_ms: sf + sb - layer_train,
        data_upload_ms,
        attention_fused_forward_ms: fused,
        conv,
        group_norm_folded: norm,
        forward_total_ms,
        train_step_ms,
        split_total_ms: sf + sb + so,
    }
}

/// The breakdown as text, percentages of the real forward and step.
pub(super) fn print(b: &Breakdown) {
    let step = b.split_total_ms;
    let fwd = b.forward_total_ms;
    println!(
        "  step split (real net): forward {:.1} ms, backward {:.1} ms, optimiser {:.1} ms (sum {:.1} ms)",
        b.step_forward_ms, b.step_backward_ms, b.step_optimizer_ms, step
    );
    println!(
        "  {:<20} {:>6} {:>18} {:>18} {:>18}",
        "layer kind", "layers", "fwd (infer)", "fwd (autodiff)", "backward"
    );
    for k in &b.kinds {
        println!(
            "  {:<20} {:>6} {:>9.1} ms {:>4.0}% {:>9.1} ms {:>4.0}% {:>9.1} ms {:>4.0}%",
            k.kind,
            k.layers,
            k.forward_ms,
            100.0 * k.forward_ms / fwd,
            k.forward_train_ms,
            100.0 * k.forward_train_ms / step,
            k.backward_ms,
            100.0 * k.backward_ms / step
        );
    }
    println!(
        "  other (pool, cat, pad/slice, adds, time embedding, loss, autodiff bookkeeping): forward {:.1} ms ({:.0}%), step {:.1} ms ({:.0}%)",
        b.forward_other_ms,
        100.0 * b.forward_other_ms / fwd,
        b.step_other_ms,
        100.0 * b.step_other_ms / step
    );
    println!(
        "  optimiser {:.0}% of the step; data upload {:.2} ms",
        100.0 * b.step_optimizer_ms / step,
        b.data_upload_ms
    );
    let c = &b.conv;
    println!(
        "  conv backward on Flex: x grad {:.1} ms, weight grad {:.1} ms, bias grad {:.1} ms",
        c.x_grad_ms, c.weight_grad_ms, c.bias_grad_ms
    );
    println!(
        "  {} stride-1 convs, burn Conv2d vs im2col+matmul in tensor ops: forward {:.1} vs {:.1} ms, forward+backward {:.1} vs {:.1} ms",
        c.stride1_layers, c.conv2d_forward_ms, c.im2col_forward_ms, c.conv2d_train_ms, c.im2col_train_ms
    );
    if c.pointwise_layers > 0 {
        println!(
            "  of which {} 1x1 convs, burn Conv2d vs matmul: forward+backward {:.1} vs {:.1} ms",
            c.pointwise_layers, c.pointwise_conv2d_train_ms, c.pointwise_matmul_train_ms
        );
    }
    if let Some(d) = &b.group_norm_folded {
        println!(
            "  {} group norms, burn GroupNorm vs folded affine: forward {:.1} vs {:.1} ms, forward+backward {:.1} vs {:.1} ms",
            d.layers, d.burn_forward_ms, d.folded_forward_ms, d.burn_train_ms, d.folded_train_ms
        );
    }
    if let Some(f) = b.attention_fused_forward_ms {
        println!("  attention core through burn's fused module::attention (inference): {f:.2} ms");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::module::Module;
    use pgrf_nn::{SidUnetConfig, Sr3Config};

    /// Rows and layer counts of the breakdown for `layers`.
    fn rows(layers: &[Layer]) -> BTreeMap<String, usize> {
        let mut rows = BTreeMap::new();
        for op in Op::list(layers) {
            *rows.entry(op.kind()).or_default() += 1;
        }
        rows
    }

    #[test]
    fn the_default_networks_give_the_rows_benchmarks_md_counts() {
        let device = Default::default();
        let unet = SidUnetConfig::new().init::<Cpu>(&device);
        let layers = unet.layers(128, 128);
        let want: BTreeMap<String, usize> = [
            ("conv 3x3", 18),
            ("conv 1x1", 1),
            ("conv transpose 2x2", 4),
            ("leaky relu", 18),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect();
        assert_eq!(rows(&layers), want);
        let ops = Op::list(&layers);
        assert!(!ops[0].grad_x && ops[1..].iter().all(|o| o.grad_x));
        // 128 x 128 halves four times; the bottom level runs at 8 x 8.
        assert!(layers.contains(&Layer::LeakyRelu {
            channels: 512,
            h: 8,
            w: 8
        }));
        drop(unet);

        let sr3 = Sr3Config::new().init::<Cpu>(&device).unwrap();
        assert_eq!(sr3.num_params(), 97_818_436);
        let layers = sr3.layers(128, 128);
        // BENCHMARKS.md's SR3 table: 60 conv 3x3 + 4 stride-2, 30 conv 1x1,
        // 61 GroupNorm, 55 SiLU on feature maps (+ the time MLP's), 6
        // attention cores; 29 linear layers (time MLP, block embeddings).
        let want: BTreeMap<String, usize> = [
            ("conv 3x3", 60),
            ("conv 3x3 stride 2", 4),
            ("conv 1x1", 30),
            ("group norm", 61),
            ("silu", 56),
            ("attention core", 6),
            ("linear", 29),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect();
        assert_eq!(rows(&layers), want);
        let tokens: Vec<usize> = layers
            .iter()
            .filter_map(|l| match *l {
                Layer::Attention { h, w, .. } => Some(h * w),
                _ => None,
            })
            .collect();
        // Level 3 (16 x 16) in two down and three up blocks, the first
        // middle block at level 4 (8 x 8).
        assert_eq!(tokens.iter().filter(|&&t| t == 256).count(), 5);
        assert_eq!(tokens.iter().filter(|&&t| t == 64).count(), 1);
    }

    #[test]
    fn im2col_convolution_equals_burns() {
        let device = Default::default();
        for (k, p) in [(3, 1), (1, 0)] {
            let conv = Conv2dConfig::new([3, 5], [k, k])
                .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
                .init::<Cpu>(&device);
            let x = uniform::<Cpu>([2, 3, 6, 7], &device);
            let w = conv.weight.val().reshape([1, 5, 3 * k * k]);
            let b = conv.bias.as_ref().unwrap().val().reshape([1, 5, 1]);
            let d: f32 = (conv_im2col(x.clone(), w, b, k) - conv.forward(x))
                .abs()
                .max()
                .into_scalar();
            assert!(d < 1e-5, "k {k}: {d}");
        }
    }

    #[test]
    fn fused_attention_equals_the_networks() {
        let device = Default::default();
        let qkv = Tensor::<Cpu, 3>::random([2, 3 * 4, 10], Distribution::Normal(0.0, 1.0), &device);
        let d: f32 = (attention_fused(qkv.clone(), 4) - attention_core(qkv, 4))
            .abs()
            .max()
            .into_scalar();
        assert!(d < 1e-4, "{d}");
    }
}
