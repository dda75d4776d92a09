//! `pgrf bench train`: forward and training-step time of the two networks on
//! the CPU (burn's Flex backend), the numbers bench/train_torch.py is held
//! against.
//!
//! Forward runs on the inference backend (no autodiff); the training step is
//! `pgrf_nn::step::denoiser_step` / `flow_step` with burn's Adam: forward,
//! L1 loss, backward, optimiser update. With `--breakdown` the step is also
//! split into forward / backward / optimiser on the real network, and every
//! convolution, GroupNorm and attention core of the network is timed on its
//! own at the shape it runs at (forward on both backends, backward through
//! autodiff), which attributes the step to the layer kinds.

use crate::cmd::bench::median;
use anyhow::{ensure, Result};
use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use burn::nn::{GroupNorm, GroupNormConfig, LeakyRelu, LeakyReluConfig, PaddingConfig2d};
use burn::optim::{AdamConfig, GradientsParams, Optimizer};
use burn::tensor::activation::{silu, softmax};
use burn::tensor::backend::Backend;
use burn::tensor::ops::{AttentionModuleOptions, ConvOptions, ModuleOps, PadMode};
use burn::tensor::{Distribution, ElementConversion, Tensor, TensorData};
use clap::{Args, ValueEnum};
use pgrf_nn::backend::{Cpu, CpuTrain};
use pgrf_nn::step::{denoiser_step, flow_step, interpolate_path, l1};
use pgrf_nn::{SidUnetConfig, Sr3Config};
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Instant;

/// The burn version the workspace pins.
const BURN_VERSION: &str = "0.21.0";
const LR: f64 = 1e-4;

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum NetChoice {
    Unet,
    Sr3,
    Both,
}

#[derive(Args, Debug)]
pub struct TrainArgs {
    /// Which network(s) to time.
    #[arg(long, value_enum, default_value = "both")]
    pub net: NetChoice,
    /// Batch size.
    #[arg(long, default_value_t = 2)]
    pub batch: usize,
    /// Side of the (square) packed input crop; a multiple of 16.
    #[arg(long, default_value_t = 128)]
    pub size: usize,
    /// Width of the SID U-Net's first level.
    #[arg(long, default_value_t = 32)]
    pub width: usize,
    /// Timed iterations (medians are reported).
    #[arg(long, default_value_t = 10)]
    pub iters: usize,
    /// Untimed warm-up iterations.
    #[arg(long, default_value_t = 2)]
    pub warmup: usize,
    /// Also split the step into forward / backward / optimiser and time every
    /// convolution, GroupNorm and attention of the network on its own.
    #[arg(long)]
    pub breakdown: bool,
    /// Time the training step only (no forward timing): for profilers.
    #[arg(long)]
    pub step_only: bool,
    /// Print one JSON line instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct NetResult {
    params: usize,
    forward_ms: f64,
    forward_ms_min: f64,
    train_step_ms: f64,
    train_step_ms_min: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    breakdown: Option<Breakdown>,
}

#[derive(Serialize)]
struct Report {
    burn: &'static str,
    backend: &'static str,
    threads: usize,
    batch: usize,
    size: usize,
    width: usize,
    iters: usize,
    warmup: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    unet: Option<NetResult>,
    #[serde(skip_serializing_if = "Option::is_none")]
    sr3: Option<NetResult>,
}

pub fn run(a: &TrainArgs) -> Result<()> {
    ensure!(a.iters > 0, "--iters must be at least 1");
    ensure!(a.batch > 0, "--batch must be at least 1");
    ensure!(
        a.size > 0 && a.size.is_multiple_of(16),
        "--size must be a positive multiple of 16"
    );
    let want = |n| a.net == NetChoice::Both || a.net == n;
    let unet = if want(NetChoice::Unet) {
        Some(bench_unet(a)?)
    } else {
        None
    };
    let sr3 = if want(NetChoice::Sr3) {
        Some(bench_sr3(a)?)
    } else {
        None
    };
    let r = Report {
        burn: BURN_VERSION,
        backend: "flex",
        threads: rayon::current_num_threads(),
        batch: a.batch,
        size: a.size,
        width: a.width,
        iters: a.iters,
        warmup: a.warmup,
        unet,
        sr3,
    };
    if a.json {
        println!("{}", serde_json::to_string(&r)?);
        return Ok(());
    }
    println!(
        "burn {} (Flex CPU), {} threads, batch {} x 4 x {} x {}, median of {} after {} warm-up",
        r.burn, r.threads, r.batch, r.size, r.size, r.iters, r.warmup
    );
    for (name, res) in [("SID U-Net", &r.unet), ("SR3", &r.sr3)] {
        let Some(res) = res else { continue };
        println!(
            "{name:<10} {:>11} params  forward {:>8.1} ms  train step {:>8.1} ms",
            res.params, res.forward_ms, res.train_step_ms
        );
        if let Some(b) = &res.breakdown {
            print_breakdown(b);
        }
    }
    Ok(())
}

/// Median and minimum of `iters` timed calls after `warmup` untimed ones, ms.
fn time_it(warmup: usize, iters: usize, mut f: impl FnMut()) -> (f64, f64) {
    for _ in 0..warmup {
        f();
    }
    let mut ts: Vec<f64> = (0..iters)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    if ts.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let min = ts.iter().cloned().fold(f64::MAX, f64::min);
    (median(&mut ts), min)
}

fn uniform<B: Backend>(shape: [usize; 4], device: &B::Device) -> Tensor<B, 4> {
    Tensor::random(shape, Distribution::Uniform(0.0, 1.0), device)
}

fn sync<B: Backend>(device: &B::Device) {
    B::sync(device).expect("backend sync");
}

fn bench_unet(a: &TrainArgs) -> Result<NetResult> {
    let device = Default::default();
    let shape = [a.batch, 4, a.size, a.size];
    let cfg = SidUnetConfig::new().with_width(a.width);

    let net = cfg.init::<Cpu>(&device);
    let params = net.num_params();
    let noisy = uniform::<Cpu>(shape, &device);
    let fwd_iters = if a.step_only { 0 } else { a.iters };
    let (forward_ms, forward_ms_min) = time_it(a.warmup.min(fwd_iters), fwd_iters, || {
        std::hint::black_box(net.forward(noisy.clone()));
        sync::<Cpu>(&device);
    });
    drop(net);

    let mut net = Some(cfg.init::<CpuTrain>(&device));
    let mut optim = AdamConfig::new().init();
    let noisy = uniform::<CpuTrain>(shape, &device);
    let clean = uniform::<CpuTrain>(shape, &device);
    let (train_step_ms, train_step_ms_min) = time_it(a.warmup, a.iters, || {
        let (n, loss) = denoiser_step(
            net.take().expect("net"),
            &mut optim,
            noisy.clone(),
            clean.clone(),
            LR,
        );
        std::hint::black_box(loss);
        net = Some(n);
    });

    let breakdown = if a.breakdown {
        let mut net = net.take().expect("net");
        let mut split = Vec::new();
        for i in 0..a.iters.min(5) + 1 {
            let t0 = Instant::now();
            let loss = l1(net.forward(noisy.clone()), clean.clone());
            let _: f32 = loss.clone().into_scalar().elem();
            let t1 = Instant::now();
            let grads = loss.backward();
            let t2 = Instant::now();
            let grads = GradientsParams::from_grads(grads, &net);
            net = optim.step(LR, net, grads);
            sync::<CpuTrain>(&device);
            let t3 = Instant::now();
            if i > 0 {
                split.push([t1 - t0, t2 - t1, t3 - t2].map(|d| d.as_secs_f64() * 1e3));
            }
        }
        let ops = unet_ops(a.width, a.size);
        Some(breakdown(
            a.batch,
            a.size,
            split,
            &ops,
            forward_ms,
            train_step_ms,
            2,
        ))
    } else {
        None
    };
    Ok(NetResult {
        params,
        forward_ms,
        forward_ms_min,
        train_step_ms,
        train_step_ms_min,
        breakdown,
    })
}

fn bench_sr3(a: &TrainArgs) -> Result<NetResult> {
    let device = Default::default();
    let shape = [a.batch, 4, a.size, a.size];
    let cfg = Sr3Config::new();
    let t_host: Vec<f32> = (0..a.batch)
        .map(|i| (i as f32 + 0.5) / a.batch as f32)
        .collect();

    let net = cfg.init::<Cpu>(&device).map_err(anyhow::Error::msg)?;
    let params = net.num_params();
    let cond = uniform::<Cpu>(shape, &device);
    let x1 = uniform::<Cpu>(shape, &device);
    let x0 = Tensor::<Cpu, 4>::random(shape, Distribution::Normal(0.0, 1.0), &device);
    let t = Tensor::<Cpu, 1>::from_floats(t_host.as_slice(), &device);
    let xt = interpolate_path(x1, x0, t.clone());
    let fwd_iters = if a.step_only { 0 } else { a.iters };
    let (forward_ms, forward_ms_min) = time_it(a.warmup.min(fwd_iters), fwd_iters, || {
        std::hint::black_box(net.forward(xt.clone(), cond.clone(), t.clone()));
        sync::<Cpu>(&device);
    });
    drop(net);

    let mut net = Some(cfg.init::<CpuTrain>(&device).map_err(anyhow::Error::msg)?);
    let mut optim = AdamConfig::new().init();
    let cond = uniform::<CpuTrain>(shape, &device);
    let x1 = uniform::<CpuTrain>(shape, &device);
    let x0 = Tensor::<CpuTrain, 4>::random(shape, Distribution::Normal(0.0, 1.0), &device);
    let t = Tensor::<CpuTrain, 1>::from_floats(t_host.as_slice(), &device);
    let (train_step_ms, train_step_ms_min) = time_it(a.warmup, a.iters, || {
        let (n, loss) = flow_step(
            net.take().expect("net"),
            &mut optim,
            cond.clone(),
            x1.clone(),
            x0.clone(),
            t.clone(),
            LR,
        );
        std::hint::black_box(loss);
        net = Some(n);
    });

    let breakdown = if a.breakdown {
        let mut net = net.take().expect("net");
        let mut split = Vec::new();
        for i in 0..a.iters.min(5) + 1 {
            let t0 = Instant::now();
            let xt = interpolate_path(x1.clone(), x0.clone(), t.clone());
            let v = net.forward(xt, cond.clone(), t.clone());
            let loss = l1(x1.clone() - x0.clone(), v);
            let _: f32 = loss.clone().into_scalar().elem();
            let t1 = Instant::now();
            let grads = loss.backward();
            let t2 = Instant::now();
            let grads = GradientsParams::from_grads(grads, &net);
            net = optim.step(LR, net, grads);
            sync::<CpuTrain>(&device);
            let t3 = Instant::now();
            if i > 0 {
                split.push([t1 - t0, t2 - t1, t3 - t2].map(|d| d.as_secs_f64() * 1e3));
            }
        }
        let ops = sr3_ops(&cfg, a.size);
        Some(breakdown(
            a.batch,
            a.size,
            split,
            &ops,
            forward_ms,
            train_step_ms,
            4,
        ))
    } else {
        None
    };
    Ok(NetResult {
        params,
        forward_ms,
        forward_ms_min,
        train_step_ms,
        train_step_ms_min,
        breakdown,
    })
}

// ---------------------------------------------------------------------------
// Layer-level breakdown
// ---------------------------------------------------------------------------

/// One layer of a network at the shape it runs at (input side `h` x `w`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Op {
    /// k x k convolution, padding k / 2; `grad_x`: the input needs a gradient
    /// (false only for the first layer, whose input is data).
    Conv {
        cin: usize,
        cout: usize,
        k: usize,
        stride: usize,
        h: usize,
        w: usize,
        grad_x: bool,
    },
    /// 2 x 2 stride-2 transposed convolution.
    ConvT {
        cin: usize,
        cout: usize,
        h: usize,
        w: usize,
    },
    GroupNorm {
        c: usize,
        groups: usize,
        h: usize,
        w: usize,
    },
    /// LeakyReLU(0.2) (SID U-Net).
    LeakyRelu { c: usize, h: usize, w: usize },
    /// SiLU (SR3).
    Silu { c: usize, h: usize, w: usize },
    /// pgrf's single-head attention core: from the qkv projection
    /// `(n, 3c, h, w)` to the attended values `(n, c, h, w)` (the 1x1 qkv and
    /// output convolutions are counted as convolutions).
    Attention { c: usize, h: usize, w: usize },
}

impl Op {
    fn kind(&self) -> &'static str {
        match self {
            Op::Conv { k: 1, .. } => "conv 1x1",
            Op::Conv { stride: 2, .. } => "conv 3x3 stride 2",
            Op::Conv { .. } => "conv 3x3",
            Op::ConvT { .. } => "conv transpose 2x2",
            Op::GroupNorm { .. } => "group norm",
            Op::LeakyRelu { .. } => "leaky relu",
            Op::Silu { .. } => "silu",
            Op::Attention { .. } => "attention core",
        }
    }

    fn input_shape(&self, n: usize) -> [usize; 4] {
        match *self {
            Op::Conv { cin, h, w, .. } | Op::ConvT { cin, h, w, .. } => [n, cin, h, w],
            Op::GroupNorm { c, h, w, .. } | Op::LeakyRelu { c, h, w } | Op::Silu { c, h, w } => {
                [n, c, h, w]
            }
            Op::Attention { c, h, w } => [n, 3 * c, h, w],
        }
    }

    fn grad_x(&self) -> bool {
        match *self {
            Op::Conv { grad_x, .. } => grad_x,
            _ => true,
        }
    }
}

fn conv(cin: usize, cout: usize, k: usize, stride: usize, side: usize) -> Op {
    Op::Conv {
        cin,
        cout,
        k,
        stride,
        h: side,
        w: side,
        grad_x: true,
    }
}

fn first(op: Op) -> Op {
    match op {
        Op::Conv {
            cin,
            cout,
            k,
            stride,
            h,
            w,
            ..
        } => Op::Conv {
            cin,
            cout,
            k,
            stride,
            h,
            w,
            grad_x: false,
        },
        other => other,
    }
}

fn lrelu(c: usize, s: usize) -> Op {
    Op::LeakyRelu { c, h: s, w: s }
}

fn silu_op(c: usize, s: usize) -> Op {
    Op::Silu { c, h: s, w: s }
}

/// The layers of `SidUnetConfig` (4 -> 4) at width `w`, in order.
fn unet_ops(w: usize, side: usize) -> Vec<Op> {
    let widths = [w, 2 * w, 4 * w, 8 * w, 16 * w];
    let mut ops = Vec::new();
    let mut cin = 4;
    for (level, &c) in widths.iter().enumerate() {
        let s = side >> level;
        let c1 = conv(cin, c, 3, 1, s);
        ops.push(if level == 0 { first(c1) } else { c1 });
        ops.push(lrelu(c, s));
        ops.push(conv(c, c, 3, 1, s));
        ops.push(lrelu(c, s));
        cin = c;
    }
    for level in (0..4).rev() {
        let (hi, lo) = (widths[level + 1], widths[level]);
        let s = side >> level;
        ops.push(Op::ConvT {
            cin: hi,
            cout: lo,
            h: s / 2,
            w: s / 2,
        });
        ops.push(conv(2 * lo, lo, 3, 1, s));
        ops.push(lrelu(lo, s));
        ops.push(conv(lo, lo, 3, 1, s));
        ops.push(lrelu(lo, s));
    }
    ops.push(conv(w, 4, 1, 1, side));
    ops
}

/// The layers of an `Sr3Config` network, walked the way `Sr3Config::init`
/// and `Sr3Unet::forward` build and run it.
fn sr3_ops(cfg: &Sr3Config, side: usize) -> Vec<Op> {
    let inner = cfg.inner_channels;
    let g = cfg.norm_groups;
    let gn = |c, s| Op::GroupNorm {
        c,
        groups: g,
        h: s,
        w: s,
    };
    let block = |ops: &mut Vec<Op>, cin: usize, cout: usize, attn: bool, s: usize| {
        ops.push(gn(cin, s));
        ops.push(silu_op(cin, s));
        ops.push(conv(cin, cout, 3, 1, s));
        ops.push(gn(cout, s));
        ops.push(silu_op(cout, s));
        ops.push(conv(cout, cout, 3, 1, s));
        if cin != cout {
            ops.push(conv(cin, cout, 1, 1, s));
        }
        if attn {
            ops.push(gn(cout, s));
            ops.push(conv(cout, 3 * cout, 1, 1, s));
            ops.push(Op::Attention {
                c: cout,
                h: s,
                w: s,
            });
            ops.push(conv(cout, cout, 1, 1, s));
        }
    };
    let levels = cfg.channel_mults.len();
    let mut ops = vec![first(conv(cfg.in_channels, inner, 3, 1, side))];
    let mut feats = vec![inner];
    let mut pre = inner;
    let mut s = side;
    for (level, mult) in cfg.channel_mults.iter().enumerate() {
        let ch = inner * mult;
        let attn = cfg.attn_levels.contains(&level);
        for _ in 0..cfg.res_blocks {
            block(&mut ops, pre, ch, attn, s);
            feats.push(ch);
            pre = ch;
        }
        if level + 1 < levels {
            ops.push(conv(pre, pre, 3, 2, s));
            s /= 2;
            feats.push(pre);
        }
    }
    block(&mut ops, pre, pre, true, s);
    block(&mut ops, pre, pre, false, s);
    for level in (0..levels).rev() {
        let ch = inner * cfg.channel_mults[level];
        let attn = cfg.attn_levels.contains(&level);
        for _ in 0..=cfg.res_blocks {
            let skip = feats.pop().expect("one feature per down step");
            block(&mut ops, pre + skip, ch, attn, s);
            pre = ch;
        }
        if level > 0 {
            s *= 2;
            ops.push(conv(pre, pre, 3, 1, s));
        }
    }
    ops.push(gn(pre, side));
    ops.push(silu_op(pre, side));
    ops.push(conv(pre, cfg.out_channels, 3, 1, side));
    ops
}

/// A layer built on backend `B`.
enum Layer<B: Backend> {
    Conv(Conv2d<B>),
    ConvT(ConvTranspose2d<B>),
    Norm(GroupNorm<B>),
    LeakyRelu(LeakyRelu),
    Silu,
    Attention(usize),
}

impl<B: Backend> Layer<B> {
    fn build(op: &Op, device: &B::Device) -> Self {
        match *op {
            Op::Conv {
                cin,
                cout,
                k,
                stride,
                ..
            } => {
                let p = k / 2;
                Layer::Conv(
                    Conv2dConfig::new([cin, cout], [k, k])
                        .with_stride([stride, stride])
                        .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
                        .init(device),
                )
            }
            Op::ConvT { cin, cout, .. } => Layer::ConvT(
                ConvTranspose2dConfig::new([cin, cout], [2, 2])
                    .with_stride([2, 2])
                    .init(device),
            ),
            Op::GroupNorm { c, groups, .. } => {
                Layer::Norm(GroupNormConfig::new(groups, c).init(device))
            }
            Op::LeakyRelu { .. } => {
                Layer::LeakyRelu(LeakyReluConfig::new().with_negative_slope(0.2).init())
            }
            Op::Silu { .. } => Layer::Silu,
            Op::Attention { c, .. } => Layer::Attention(c),
        }
    }

    fn forward(&self, x: Tensor<B, 4>) -> Tensor<B, 4> {
        match self {
            Layer::Conv(m) => m.forward(x),
            Layer::ConvT(m) => m.forward(x),
            Layer::Norm(m) => m.forward(x),
            Layer::LeakyRelu(m) => m.forward(x),
            Layer::Silu => silu(x),
            Layer::Attention(c) => {
                let [n, _, h, w] = x.dims();
                attention_core(x.reshape([n, 3 * c, h * w]), *c).reshape([n, *c, h, w])
            }
        }
    }
}

/// Exactly the formulation of `SelfAttention::forward` in crates/nn/src/sr3.rs.
fn attention_core<B: Backend>(qkv: Tensor<B, 3>, c: usize) -> Tensor<B, 3> {
    let [n, _, hw] = qkv.dims();
    let q = qkv.clone().slice([0..n, 0..c, 0..hw]);
    let k = qkv.clone().slice([0..n, c..2 * c, 0..hw]);
    let v = qkv.slice([0..n, 2 * c..3 * c, 0..hw]);
    let scores = q.swap_dims(1, 2).matmul(k) / (c as f64).sqrt();
    let weights = softmax(scores, 2);
    v.matmul(weights.swap_dims(1, 2))
}

/// The same attention through burn's fused `module::attention` (Flex has a
/// native kernel; under autodiff burn 0.21 falls back to separate ops).
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

/// SR3's GroupNorm as the network runs it (folded affine, pgrf_nn::norm).
fn group_norm_folded<B: Backend>(x: Tensor<B, 4>, norm: &GroupNorm<B>) -> Tensor<B, 4> {
    pgrf_nn::norm::group_norm(norm, x)
}

/// (inference forward, autodiff forward + backward) of `group_norm_folded`, ms.
fn time_gn_folded(op: &Op, n: usize, reps: usize) -> (f64, f64) {
    let Op::GroupNorm { c, groups, h, w } = *op else {
        return (0.0, 0.0);
    };
    let device = Default::default();
    let m = GroupNormConfig::new(groups, c).init::<Cpu>(&device);
    let x = uniform::<Cpu>([n, c, h, w], &device);
    let fwd = time_it(1, reps, || {
        std::hint::black_box(group_norm_folded(x.clone(), &m));
    })
    .0;
    let m = GroupNormConfig::new(groups, c).init::<CpuTrain>(&device);
    let mut ts = Vec::new();
    for i in 0..reps + 1 {
        let x = uniform::<CpuTrain>([n, c, h, w], &device).require_grad();
        let t0 = Instant::now();
        let grads = group_norm_folded(x, &m).sum().backward();
        sync::<CpuTrain>(&device);
        std::hint::black_box(grads);
        if i > 0 {
            ts.push(t0.elapsed().as_secs_f64() * 1e3);
        }
    }
    (fwd, median(&mut ts))
}

fn time_forward(op: &Op, n: usize, reps: usize) -> f64 {
    let device = Default::default();
    let layer = Layer::<Cpu>::build(op, &device);
    let x = uniform::<Cpu>(op.input_shape(n), &device);
    time_it(1, reps, || {
        std::hint::black_box(layer.forward(x.clone()));
        sync::<Cpu>(&device);
    })
    .0
}

fn time_train(op: &Op, n: usize, reps: usize) -> (f64, f64) {
    let device = Default::default();
    let layer = Layer::<CpuTrain>::build(op, &device);
    let (mut fwd, mut bwd) = (Vec::new(), Vec::new());
    for i in 0..reps + 1 {
        let x = uniform::<CpuTrain>(op.input_shape(n), &device);
        let x = if op.grad_x() { x.require_grad() } else { x };
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
    let Op::Conv {
        cin,
        cout,
        k,
        stride,
        h,
        w,
        grad_x,
    } = *op
    else {
        return (0.0, 0.0, 0.0);
    };
    let device = Default::default();
    let p = k / 2;
    let options = ConvOptions::new([stride, stride], [p, p], [1, 1], 1);
    let (ho, wo) = ((h + 2 * p - k) / stride + 1, (w + 2 * p - k) / stride + 1);
    let prim = |t: Tensor<Cpu, 4>| t.into_primitive().tensor();
    let x = prim(uniform::<Cpu>([n, cin, h, w], &device));
    let weight = prim(uniform::<Cpu>([cout, cin, k, k], &device));
    let g = prim(uniform::<Cpu>([n, cout, ho, wo], &device));
    let bias = Tensor::<Cpu, 1>::zeros([cout], &device)
        .into_primitive()
        .tensor();
    let xg = if grad_x {
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

/// A stride-1 k x k convolution written with tensor ops only (zero pad, k*k
/// shifted views concatenated = im2col, one batched matmul), so that autodiff
/// derives its backward from matmul, slice and pad: `w` is
/// `(1, cout, cin*k*k)`, `b` is `(1, cout, 1)`.
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
/// shape of `op` (a stride-1 convolution), ms.
fn time_im2col(op: &Op, n: usize, reps: usize) -> (f64, f64) {
    let Op::Conv {
        cin,
        cout,
        k,
        h,
        w,
        grad_x,
        ..
    } = *op
    else {
        return (0.0, 0.0);
    };
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
        let x = if grad_x { x.require_grad() } else { x };
        let t0 = Instant::now();
        let grads = conv_im2col(x, wt.clone(), bt.clone(), k).sum().backward();
        sync::<CpuTrain>(&device);
        std::hint::black_box(grads);
        if i > 0 {
            ts.push(t0.elapsed().as_secs_f64() * 1e3);
        }
    }
    (fwd, median(&mut ts))
}

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
    /// (3x3 and 1x1 convolutions; transposed convolutions not included), ms.
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

#[derive(Serialize)]
struct KindTime {
    kind: &'static str,
    layers: usize,
    forward_ms: f64,
    forward_train_ms: f64,
    backward_ms: f64,
}

#[derive(Serialize)]
struct Breakdown {
    /// Real network, median over a few steps: forward (with loss), backward,
    /// optimiser (gradient collection + Adam update), ms.
    step_forward_ms: f64,
    step_backward_ms: f64,
    step_optimizer_ms: f64,
    /// Per layer kind, summed over the network's layers, each timed alone.
    kinds: Vec<KindTime>,
    /// Inference forward not covered by the timed layers (activations,
    /// pooling, concatenation, padding, interpolation, adds), ms.
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
    /// GroupNorm layers: burn's `GroupNorm` against `group_norm_folded`,
    /// inference forward and autodiff forward + backward, ms.
    #[serde(skip_serializing_if = "Option::is_none")]
    group_norm_folded: Option<NormDetail>,
    forward_total_ms: f64,
    /// The step's median from the main timing loop, ms.
    train_step_ms: f64,
    /// Sum of the split above (percentages are of this), ms.
    split_total_ms: f64,
}

fn breakdown(
    n: usize,
    side: usize,
    split: Vec<[f64; 3]>,
    ops: &[Op],
    forward_total_ms: f64,
    train_step_ms: f64,
    input_planes: usize,
) -> Breakdown {
    let reps = 3;
    let mut counts: BTreeMap<Op, usize> = BTreeMap::new();
    for op in ops {
        *counts.entry(*op).or_default() += 1;
    }
    let mut kinds: BTreeMap<&'static str, KindTime> = BTreeMap::new();
    let mut fused = None;
    let mut conv = ConvDetail::default();
    let mut norm: Option<NormDetail> = None;
    for (op, &count) in &counts {
        let f = time_forward(op, n, reps);
        let (ft, b) = time_train(op, n, reps);
        let c = count as f64;
        if let Op::GroupNorm { .. } = op {
            let (ff, ft2) = time_gn_folded(op, n, reps);
            let d = norm.get_or_insert_with(NormDetail::default);
            d.layers += count;
            d.burn_forward_ms += f * c;
            d.folded_forward_ms += ff * c;
            d.burn_train_ms += (ft + b) * c;
            d.folded_train_ms += ft2 * c;
        }
        if let Op::Conv { stride, .. } = *op {
            let (xg, wg, bg) = time_conv_grads(op, n, reps);
            conv.x_grad_ms += xg * c;
            conv.weight_grad_ms += wg * c;
            conv.bias_grad_ms += bg * c;
            if stride == 1 {
                let (af, at) = time_im2col(op, n, reps);
                conv.stride1_layers += count;
                conv.conv2d_forward_ms += f * c;
                conv.im2col_forward_ms += af * c;
                conv.conv2d_train_ms += (ft + b) * c;
                conv.im2col_train_ms += at * c;
                if let Op::Conv { k: 1, .. } = *op {
                    conv.pointwise_layers += count;
                    conv.pointwise_conv2d_train_ms += (ft + b) * c;
                    conv.pointwise_matmul_train_ms += at * c;
                }
            }
        }
        let k = kinds.entry(op.kind()).or_insert(KindTime {
            kind: op.kind(),
            layers: 0,
            forward_ms: 0.0,
            forward_train_ms: 0.0,
            backward_ms: 0.0,
        });
        k.layers += count;
        k.forward_ms += f * count as f64;
        k.forward_train_ms += ft * count as f64;
        k.backward_ms += b * count as f64;
        if let Op::Attention { c, h, w } = *op {
            let device = Default::default();
            let qkv = uniform::<Cpu>([n, 3 * c, h, w], &device).reshape([n, 3 * c, h * w]);
            let (ms, _) = time_it(1, reps, || {
                std::hint::black_box(attention_fused(qkv.clone(), c));
            });
            *fused.get_or_insert(0.0) += ms * count as f64;
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

fn print_breakdown(b: &Breakdown) {
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
        "  other (pool, cat, pad/slice, adds, embedding, loss, autodiff bookkeeping): forward {:.1} ms ({:.0}%), step {:.1} ms ({:.0}%)",
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

    #[test]
    fn folded_group_norm_matches_burns() {
        let device = Default::default();
        let mut m = GroupNormConfig::new(4, 8).init::<Cpu>(&device);
        m.gamma = m
            .gamma
            .map(|p| p.map(|_| Tensor::random([8], Distribution::Normal(1.0, 0.5), &device)));
        m.beta = m
            .beta
            .map(|p| p.map(|_| Tensor::random([8], Distribution::Normal(0.0, 0.5), &device)));
        let x = Tensor::<Cpu, 4>::random([2, 8, 5, 7], Distribution::Normal(0.3, 2.0), &device);
        let d: f32 = (group_norm_folded(x.clone(), &m) - m.forward(x))
            .abs()
            .max()
            .into_scalar();
        assert!(d < 1e-4, "max difference {d}");
    }

    #[test]
    fn layer_lists_match_the_networks() {
        // Every parameterised layer of each network appears once: the
        // convolutions' parameter count equals the network's, less GroupNorm
        // and the SR3 time MLP / per-block embedding projections.
        let conv_params = |ops: &[Op]| -> usize {
            ops.iter()
                .map(|op| match *op {
                    Op::Conv { cin, cout, k, .. } => k * k * cin * cout + cout,
                    Op::ConvT { cin, cout, .. } => 4 * cin * cout + cout,
                    Op::GroupNorm { c, .. } => 2 * c,
                    _ => 0,
                })
                .sum()
        };
        assert_eq!(conv_params(&unet_ops(32, 128)), 7_760_484);
        let cfg = Sr3Config::new();
        let ops = sr3_ops(&cfg, 128);
        let inner = cfg.inner_channels;
        let blocks = cfg.channel_mults.len() * (2 * cfg.res_blocks + 1) + 2;
        let emb: usize = {
            // One Linear(inner, cout) per residual block.
            let mut couts = Vec::new();
            for m in &cfg.channel_mults {
                couts.extend(std::iter::repeat_n(inner * m, cfg.res_blocks));
            }
            couts.extend([inner * 8, inner * 8]);
            for m in cfg.channel_mults.iter().rev() {
                couts.extend(std::iter::repeat_n(inner * m, cfg.res_blocks + 1));
            }
            assert_eq!(couts.len(), blocks);
            couts.iter().map(|&c| inner * c + c).sum()
        };
        let t_mlp = inner * 4 * inner + 4 * inner + 4 * inner * inner + inner;
        assert_eq!(conv_params(&ops) + emb + t_mlp, 97_818_436);
    }
}
