//! `pgrf-bench train`: forward and training-step time of the two networks on
//! the CPU (burn's Flex backend), the numbers bench/train_torch.py is held
//! against.
//!
//! Forward runs on the inference backend (no autodiff); the training step is
//! `pgrf_nn::step::denoiser_step` / `flow_step` with burn's Adam: forward,
//! L1 loss, backward, optimiser update. With `--breakdown` the step is also
//! split into forward / backward / optimiser on the real network, and every
//! layer the network lists (`pgrf_nn::layers`) is timed on its own at the
//! shape it runs at (train/breakdown.rs).

mod breakdown;

use anyhow::{ensure, Result};
use breakdown::Breakdown;
use burn::module::Module;
use burn::optim::adaptor::OptimizerAdaptor;
use burn::optim::{GradientsParams, Optimizer};
use burn::tensor::backend::Backend;
use burn::tensor::{Distribution, ElementConversion, Tensor};
use clap::{Args, ValueEnum};
use pgrf_core::stats::median;
use pgrf_nn::backend::{Cpu, CpuTrain};
use pgrf_nn::flow::{flow_loss, interpolate};
use pgrf_nn::ops::adam::PgrfAdam;
use pgrf_nn::step::{denoiser_loss, denoiser_step, flow_step};
use pgrf_nn::{SidUnetConfig, Sr3Config};
use serde::Serialize;
use std::time::Instant;

/// The burn version the workspace pins.
const BURN_VERSION: &str = "0.21.0";
/// Adam's learning rate (the training recipe's first one).
const LR: f64 = 1e-4;

/// The network(s) `--net` picks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum NetChoice {
    /// The SID U-Net (SPC denoiser).
    Unet,
    /// The SR3 velocity field (PGRF flow model), default configuration.
    Sr3,
    /// Both, U-Net first.
    Both,
}

/// Flags of `pgrf-bench train`.
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
    /// Whose operations the networks run: pgrf's own (the default) or
    /// burn 0.21's, for comparison in the same binary.
    #[arg(long, default_value = "pgrf")]
    pub kernels: pgrf_nn::ops::Kernels,
    /// Leave glibc's allocator at its defaults (large buffers unmapped on
    /// free and faulted in again) instead of keeping freed buffers, as
    /// `pgrf` does: measures what `pgrf_core::mem::keep_freed_buffers` buys.
    #[arg(long)]
    pub default_malloc: bool,
    /// Print one JSON line instead of text.
    #[arg(long)]
    pub json: bool,
}

/// One network's timings.
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

/// The JSON line bench/train.sh reads.
#[derive(Serialize)]
struct Report {
    burn: &'static str,
    backend: &'static str,
    kernels: String,
    malloc: &'static str,
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

/// Time the chosen networks and print the report.
pub fn run(a: &TrainArgs) -> Result<()> {
    ensure!(a.iters > 0, "--iters must be at least 1");
    ensure!(a.batch > 0, "--batch must be at least 1");
    ensure!(
        a.size > 0 && a.size.is_multiple_of(16),
        "--size must be a positive multiple of 16"
    );
    pgrf_nn::ops::set_kernels(a.kernels);
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
        kernels: a.kernels.to_string(),
        malloc: if a.default_malloc {
            "glibc defaults"
        } else {
            "freed buffers kept"
        },
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
        "burn {} (Flex CPU, {} operations, malloc: {}), {} threads, batch {} x 4 x {} x {}, median of {} after {} warm-up",
        r.burn, r.kernels, r.malloc, r.threads, r.batch, r.size, r.size, r.iters, r.warmup
    );
    for (name, res) in [("SID U-Net", &r.unet), ("SR3", &r.sr3)] {
        let Some(res) = res else { continue };
        println!(
            "{name:<10} {:>11} params  forward {:>8.1} ms  train step {:>8.1} ms",
            res.params, res.forward_ms, res.train_step_ms
        );
        if let Some(b) = &res.breakdown {
            breakdown::print(b);
        }
    }
    Ok(())
}

/// Median and minimum of `iters` timed calls after `warmup` untimed ones, ms
/// (NaN for no timed calls).
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
    let min = ts.iter().copied().fold(f64::MAX, f64::min);
    (median(&mut ts), min)
}

/// A tensor of U(0, 1) values.
fn uniform<B: Backend>(shape: [usize; 4], device: &B::Device) -> Tensor<B, 4> {
    Tensor::random(shape, Distribution::Uniform(0.0, 1.0), device)
}

/// Wait for the backend's queued work (a no-op on Flex, which runs eagerly).
fn sync<B: Backend>(device: &B::Device) {
    B::sync(device).expect("backend sync");
}

/// Steps of the forward / backward / optimiser split (after one untimed).
fn split_steps(a: &TrainArgs) -> usize {
    a.iters.min(5)
}

/// Milliseconds between consecutive instants: `[t1 - t0, t2 - t1, t3 - t2]`.
/// The real training step of `net` split into forward (loss), backward and
/// optimiser, timed `split_steps(a)` times after one untimed step.
fn split_step<M, O>(
    a: &TrainArgs,
    mut net: M,
    optim: &mut O,
    loss_of: impl Fn(&M) -> Tensor<CpuTrain, 1>,
) -> (M, Vec<[f64; 3]>)
where
    M: burn::module::AutodiffModule<CpuTrain>,
    O: Optimizer<M, CpuTrain>,
{
    let device = Default::default();
    let mut split = Vec::new();
    for i in 0..split_steps(a) + 1 {
        let t0 = Instant::now();
        let loss = loss_of(&net);
        let _: f32 = loss.clone().into_scalar().elem();
        let t1 = Instant::now();
        let grads = loss.backward();
        let t2 = Instant::now();
        let grads = GradientsParams::from_grads(grads, &net);
        net = optim.step(LR, net, grads);
        sync::<CpuTrain>(&device);
        if i > 0 {
            split.push(split_ms([t0, t1, t2, Instant::now()]));
        }
    }
    (net, split)
}

fn split_ms(t: [Instant; 4]) -> [f64; 3] {
    [0, 1, 2].map(|i| (t[i + 1] - t[i]).as_secs_f64() * 1e3)
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
    let mut optim =
        OptimizerAdaptor::<PgrfAdam, _, CpuTrain>::from(PgrfAdam::new(0.9, 0.999, 1e-8));
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
        let (net, split) = split_step(a, net.take().expect("net"), &mut optim, |n| {
            denoiser_loss(n, noisy.clone(), clean.clone())
        });
        let layers = net.layers(a.size, a.size);
        Some(breakdown::breakdown(
            a.batch,
            a.size,
            split,
            &layers,
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
    let xt = interpolate(x1, x0, t.clone());
    let fwd_iters = if a.step_only { 0 } else { a.iters };
    let (forward_ms, forward_ms_min) = time_it(a.warmup.min(fwd_iters), fwd_iters, || {
        std::hint::black_box(net.forward(xt.clone(), cond.clone(), t.clone()));
        sync::<Cpu>(&device);
    });
    drop(net);

    let mut net = Some(cfg.init::<CpuTrain>(&device).map_err(anyhow::Error::msg)?);
    let mut optim =
        OptimizerAdaptor::<PgrfAdam, _, CpuTrain>::from(PgrfAdam::new(0.9, 0.999, 1e-8));
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
        let (net, split) = split_step(a, net.take().expect("net"), &mut optim, |n| {
            flow_loss(n, cond.clone(), x1.clone(), x0.clone(), t.clone())
        });
        let layers = net.layers(a.size, a.size);
        Some(breakdown::breakdown(
            a.batch,
            a.size,
            split,
            &layers,
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
