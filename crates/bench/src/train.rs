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
use pgrf_nn::flow::{flow_loss, interpolate};
use pgrf_nn::loss::denoiser_loss;
use pgrf_nn::ops::adam::PgrfAdam;
use pgrf_nn::ops::PgrfAutodiff;
use pgrf_nn::step::{denoiser_step, flow_step};
use pgrf_nn::DeviceKind;
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
    /// cpu, or cuda (needs a build with `--features cuda`); the CPU-only
    /// `--breakdown` is refused on CUDA.
    #[arg(long, default_value = "cpu")]
    pub device: pgrf_nn::DeviceKind,
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
    backend: String,
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
    ensure!(
        !(a.breakdown && a.device == DeviceKind::Cuda),
        "--breakdown times the CPU's layers; leave it out with --device cuda"
    );
    let (unet, sr3) = pgrf_nn::ops::with_kernels(a.kernels, || {
        pgrf_nn::backend::on_train_device(a.device, Bench(a))
    })
    .map_err(|e| anyhow::anyhow!("{e}"))?;
    let r = Report {
        burn: BURN_VERSION,
        backend: match a.device {
            DeviceKind::Cpu => "flex".into(),
            DeviceKind::Cuda => pgrf_nn::backend::describe(a.device, a.kernels),
        },
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
        "burn {} ({}, {} operations, malloc: {}), {} threads, batch {} x 4 x {} x {}, median of {} after {} warm-up",
        r.burn, r.backend, r.kernels, r.malloc, r.threads, r.batch, r.size, r.size, r.iters, r.warmup
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

/// Both networks' timings on one training backend (the CPU's or CUDA's).
struct Bench<'a>(&'a TrainArgs);

impl pgrf_nn::backend::OnTrainBackend for Bench<'_> {
    type Output = (Option<NetResult>, Option<NetResult>);
    fn run<B: PgrfAutodiff>(self, device: B::Device) -> pgrf_nn::Result<Self::Output> {
        let a = self.0;
        let want = |n| a.net == NetChoice::Both || a.net == n;
        let err = |e: anyhow::Error| pgrf_nn::NnError::Invalid(format!("{e:#}"));
        let unet = if want(NetChoice::Unet) {
            Some(bench_unet::<B>(a, &device).map_err(err)?)
        } else {
            None
        };
        let sr3 = if want(NetChoice::Sr3) {
            Some(bench_sr3::<B>(a, &device).map_err(err)?)
        } else {
            None
        };
        Ok((unet, sr3))
    }
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
fn split_step<B, M, O>(
    a: &TrainArgs,
    device: &B::Device,
    mut net: M,
    optim: &mut O,
    loss_of: impl Fn(&M) -> Tensor<B, 1>,
) -> (M, Vec<[f64; 3]>)
where
    B: PgrfAutodiff,
    M: burn::module::AutodiffModule<B>,
    O: Optimizer<M, B>,
{
    let mut split = Vec::new();
    for i in 0..split_steps(a) + 1 {
        let t0 = Instant::now();
        let loss = loss_of(&net);
        let _: f32 = loss.clone().into_scalar().elem();
        let t1 = Instant::now();
        let grads = loss.backward();
        sync::<B>(device);
        let t2 = Instant::now();
        let grads = GradientsParams::from_grads(grads, &net);
        net = optim.step(LR, net, grads);
        sync::<B>(device);
        if i > 0 {
            split.push(split_ms([t0, t1, t2, Instant::now()]));
        }
    }
    (net, split)
}

fn split_ms(t: [Instant; 4]) -> [f64; 3] {
    [0, 1, 2].map(|i| (t[i + 1] - t[i]).as_secs_f64() * 1e3)
}

fn bench_unet<B: PgrfAutodiff>(a: &TrainArgs, device: &B::Device) -> Result<NetResult> {
    let shape = [a.batch, 4, a.size, a.size];
    let cfg = SidUnetConfig::new().with_width(a.width);

    let net = cfg.init::<B::InnerBackend>(device);
    let params = net.num_params();
    let noisy = uniform::<B::InnerBackend>(shape, device);
    let fwd_iters = if a.step_only { 0 } else { a.iters };
    let (forward_ms, forward_ms_min) = time_it(a.warmup.min(fwd_iters), fwd_iters, || {
        std::hint::black_box(net.forward(noisy.clone()));
        sync::<B::InnerBackend>(device);
    });
    drop(net);

    let mut net = Some(cfg.init::<B>(device));
    let mut optim = OptimizerAdaptor::<PgrfAdam, _, B>::from(PgrfAdam::new(0.9, 0.999, 1e-8));
    let noisy = uniform::<B>(shape, device);
    let clean = uniform::<B>(shape, device);
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
        sync::<B>(device);
    });

    let breakdown = if a.breakdown {
        let (net, split) = split_step(a, device, net.take().expect("net"), &mut optim, |n| {
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

fn bench_sr3<B: PgrfAutodiff>(a: &TrainArgs, device: &B::Device) -> Result<NetResult> {
    let shape = [a.batch, 4, a.size, a.size];
    let cfg = Sr3Config::new();
    let t_host: Vec<f32> = (0..a.batch)
        .map(|i| (i as f32 + 0.5) / a.batch as f32)
        .collect();

    type I<B> = <B as burn::tensor::backend::AutodiffBackend>::InnerBackend;
    let net = cfg.init::<I<B>>(device).map_err(anyhow::Error::msg)?;
    let params = net.num_params();
    let cond = uniform::<I<B>>(shape, device);
    let x1 = uniform::<I<B>>(shape, device);
    let x0 = Tensor::<I<B>, 4>::random(shape, Distribution::Normal(0.0, 1.0), device);
    let t = Tensor::<I<B>, 1>::from_floats(t_host.as_slice(), device);
    let xt = interpolate(x1, x0, t.clone());
    let fwd_iters = if a.step_only { 0 } else { a.iters };
    let (forward_ms, forward_ms_min) = time_it(a.warmup.min(fwd_iters), fwd_iters, || {
        std::hint::black_box(net.forward(xt.clone(), cond.clone(), t.clone()));
        sync::<I<B>>(device);
    });
    drop(net);

    let mut net = Some(cfg.init::<B>(device).map_err(anyhow::Error::msg)?);
    let mut optim = OptimizerAdaptor::<PgrfAdam, _, B>::from(PgrfAdam::new(0.9, 0.999, 1e-8));
    let cond = uniform::<B>(shape, device);
    let x1 = uniform::<B>(shape, device);
    let x0 = Tensor::<B, 4>::random(shape, Distribution::Normal(0.0, 1.0), device);
    let t = Tensor::<B, 1>::from_floats(t_host.as_slice(), device);
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
        sync::<B>(device);
    });

    let breakdown = if a.breakdown {
        let (net, split) = split_step(a, device, net.take().expect("net"), &mut optim, |n| {
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
