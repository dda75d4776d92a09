//! The CUDA backend against the CPU (Flex) backend on the same weights and
//! inputs: both networks' forward pass, one Adam training step of each, and
//! the built-in models restoring a small tiled frame.
//!
//! Compiled only with `--features cuda` and ignored unless asked for, since
//! they need an NVIDIA GPU: `cargo test --release --features cuda -p pgrf-nn
//! --test cuda -- --ignored`. Tolerances are stated per test, in the units
//! of the output (the inputs are in [0, 1]); each test prints the differences
//! it measured, so that `--nocapture` shows them.

#![cfg(feature = "cuda")]

use burn::optim::adaptor::OptimizerAdaptor;
use burn::tensor::backend::Backend;
use burn::tensor::{Tensor, TensorData};
use ndarray::{Array3, ArrayView3};
use pgrf_nn::backend::{Cpu, CpuTrain, Gpu, GpuTrain};
use pgrf_nn::condition::NoiseLevel;
use pgrf_nn::infer::{restore_image, ImageOptions, Restorer, SamplerChoice};
use pgrf_nn::ops::adam::PgrfAdam;
use pgrf_nn::step::{denoiser_step, flow_step};
use pgrf_nn::weights::{NoiseSource, WeightMeta};
use pgrf_nn::{model, Architecture, Net, SidUnet, SidUnetConfig, Sr3Config, Sr3Unet};
use std::path::{Path, PathBuf};

/// Deterministic values in [0, 1): a 64-bit LCG, so both backends get the
/// same bytes without a random generator of either.
fn values(n: usize, seed: u64) -> Vec<f32> {
    let mut s = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 40) as f32 / (1u64 << 24) as f32
        })
        .collect()
}

fn tensor<B: Backend>(v: &[f32], shape: [usize; 4], device: &B::Device) -> Tensor<B, 4> {
    Tensor::from_data(TensorData::new(v.to_vec(), shape), device)
}

fn host<B: Backend, const D: usize>(t: Tensor<B, D>) -> Vec<f32> {
    t.into_data().to_vec::<f32>().expect("f32 tensor")
}

/// Largest absolute difference and the largest magnitude of `a`.
fn max_diff(a: &[f32], b: &[f32]) -> (f32, f32) {
    assert_eq!(a.len(), b.len());
    let d = a.iter().zip(b).fold(0f32, |m, (x, y)| m.max((x - y).abs()));
    let mag = a.iter().fold(0f32, |m, x| m.max(x.abs()));
    (d, mag)
}

/// A seeded network of `arch` saved to a weight file, so that both backends
/// load the same bytes (the path the weight files take in every command).
fn weights(arch: Architecture, seed: u64, name: &str) -> PathBuf {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("pgrf-cuda-test");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    let net = arch.init_seeded::<Cpu>(&Default::default(), seed).unwrap();
    net.save(&path, &WeightMeta::new(arch, NoiseSource::default()))
        .unwrap();
    path
}

fn spc<B: Backend>(path: &Path) -> SidUnet<B> {
    match model::load::<B>(path, &Default::default()).unwrap().0 {
        Net::Spc(n) => n,
        Net::Pgrf(_) => panic!("expected the SID U-Net"),
    }
}

fn sr3<B: Backend>(path: &Path) -> Sr3Unet<B> {
    match model::load::<B>(path, &Default::default()).unwrap().0 {
        Net::Pgrf(n) => n,
        Net::Spc(_) => panic!("expected the SR3"),
    }
}

fn small_sr3() -> Sr3Config {
    Sr3Config::new()
        .with_inner_channels(32)
        .with_channel_mults(vec![1, 2, 2])
        .with_res_blocks(1)
        .with_attn_levels(vec![1])
}

const SHAPE: [usize; 4] = [2, 4, 64, 96];

/// Forward of the SID U-Net (width 32, 7.8 M parameters) and of an SR3 with
/// attention, f32 on both: equal to 1e-4 of the output's largest magnitude
/// (accumulation order differs between the backends' convolutions).
#[test]
#[ignore = "needs an NVIDIA GPU"]
fn forward_passes_match_the_cpu() {
    let p = weights(
        Architecture::SidUnet(SidUnetConfig::new().with_width(32)),
        11,
        "unet.safetensors",
    );
    let n = SHAPE.iter().product();
    let x = values(n, 1);
    let cpu = host(spc::<Cpu>(&p).forward(tensor::<Cpu>(&x, SHAPE, &Default::default())));
    let gpu = host(spc::<Gpu>(&p).forward(tensor::<Gpu>(&x, SHAPE, &Default::default())));
    let (d, mag) = max_diff(&cpu, &gpu);
    println!("SID U-Net forward: max |cpu - cuda| {d:.3e}, output magnitude {mag:.3e}");
    assert!(
        d <= 1e-4 * mag.max(1e-3),
        "SID U-Net forward differs by {d}"
    );

    let p = weights(Architecture::Sr3(small_sr3()), 12, "sr3.safetensors");
    let (xt, cond) = (values(n, 2), values(n, 3));
    let t = [0.25f32, 0.75];
    let run = |xt: &[f32], cond: &[f32]| {
        let dc = Default::default();
        let c = sr3::<Cpu>(&p).forward(
            tensor::<Cpu>(xt, SHAPE, &dc),
            tensor::<Cpu>(cond, SHAPE, &dc),
            Tensor::<Cpu, 1>::from_floats(t.as_slice(), &dc),
        );
        let dg = Default::default();
        let g = sr3::<Gpu>(&p).forward(
            tensor::<Gpu>(xt, SHAPE, &dg),
            tensor::<Gpu>(cond, SHAPE, &dg),
            Tensor::<Gpu, 1>::from_floats(t.as_slice(), &dg),
        );
        (host(c), host(g))
    };
    let (cpu, gpu) = run(&xt, &cond);
    let (d, mag) = max_diff(&cpu, &gpu);
    println!("SR3 forward: max |cpu - cuda| {d:.3e}, output magnitude {mag:.3e}");
    assert!(d <= 1e-4 * mag.max(1e-3), "SR3 forward differs by {d}");
}

/// One Adam step (lr 1e-3, so that the update moves the output well beyond
/// the tolerance) on the same weights and batch: the losses agree to 1e-5
/// relative and the outputs after the step to 1e-4 of their magnitude.
#[test]
#[ignore = "needs an NVIDIA GPU"]
fn one_training_step_matches_the_cpu() {
    let lr = 1e-3;
    let n = SHAPE.iter().product();
    let (a, b, c) = (values(n, 4), values(n, 5), values(n, 6));
    let adam = || PgrfAdam::new(0.9, 0.999, 1e-8);

    let p = weights(
        Architecture::SidUnet(SidUnetConfig::new().with_width(16)),
        13,
        "unet16.safetensors",
    );
    let dc = Default::default();
    let mut oc = OptimizerAdaptor::<PgrfAdam, _, CpuTrain>::from(adam());
    let (nc, lc) = denoiser_step(
        spc::<CpuTrain>(&p),
        &mut oc,
        tensor(&a, SHAPE, &dc),
        tensor(&b, SHAPE, &dc),
        lr,
    );
    let dg = Default::default();
    let mut og = OptimizerAdaptor::<PgrfAdam, _, GpuTrain>::from(adam());
    let (ng, lg) = denoiser_step(
        spc::<GpuTrain>(&p),
        &mut og,
        tensor(&a, SHAPE, &dg),
        tensor(&b, SHAPE, &dg),
        lr,
    );
    let before = host(spc::<Cpu>(&p).forward(tensor(&a, SHAPE, &Default::default())));
    let cpu = host(nc.forward(tensor(&a, SHAPE, &dc)));
    let gpu = host(ng.forward(tensor(&a, SHAPE, &dg)));
    let (d, mag) = max_diff(&cpu, &gpu);
    let (moved, _) = max_diff(&cpu, &before);
    println!(
        "SID U-Net step: loss cpu {lc:.7} cuda {lg:.7}; output after the step: max |cpu - cuda| {d:.3e}, moved by the step {moved:.3e}, magnitude {mag:.3e}"
    );
    assert!((lc - lg).abs() <= 1e-5 * lc.abs(), "losses {lc} vs {lg}");
    assert!(
        moved > 10.0 * d,
        "the step moved the output by {moved}, the backends differ by {d}"
    );
    assert!(
        d <= 1e-4 * mag.max(1e-3),
        "SID U-Net after a step differs by {d}"
    );

    let p = weights(Architecture::Sr3(small_sr3()), 14, "sr3s.safetensors");
    let t = [0.3f32, 0.8];
    let x0: Vec<f32> = values(n, 7).iter().map(|v| 2.0 * v - 1.0).collect();
    let mut oc = OptimizerAdaptor::<PgrfAdam, _, CpuTrain>::from(adam());
    let (nc, lc) = flow_step(
        sr3::<CpuTrain>(&p),
        &mut oc,
        tensor(&a, SHAPE, &dc),
        tensor(&b, SHAPE, &dc),
        tensor(&x0, SHAPE, &dc),
        Tensor::from_floats(t.as_slice(), &dc),
        lr,
    );
    let mut og = OptimizerAdaptor::<PgrfAdam, _, GpuTrain>::from(adam());
    let (ng, lg) = flow_step(
        sr3::<GpuTrain>(&p),
        &mut og,
        tensor(&a, SHAPE, &dg),
        tensor(&b, SHAPE, &dg),
        tensor(&x0, SHAPE, &dg),
        Tensor::from_floats(t.as_slice(), &dg),
        lr,
    );
    let cpu = host(nc.forward(
        tensor(&c, SHAPE, &dc),
        tensor(&a, SHAPE, &dc),
        Tensor::from_floats(t.as_slice(), &dc),
    ));
    let gpu = host(ng.forward(
        tensor(&c, SHAPE, &dg),
        tensor(&a, SHAPE, &dg),
        Tensor::from_floats(t.as_slice(), &dg),
    ));
    let (d, mag) = max_diff(&cpu, &gpu);
    println!(
        "SR3 step: loss cpu {lc:.7} cuda {lg:.7}; output after the step: max |cpu - cuda| {d:.3e}, magnitude {mag:.3e}"
    );
    assert!((lc - lg).abs() <= 1e-5 * lc.abs(), "losses {lc} vs {lg}");
    assert!(d <= 1e-4 * mag.max(1e-3), "SR3 after a step differs by {d}");
}

/// A smooth scene with an edge and fine grain, amplified-capture range.
fn scene(h: usize, w: usize) -> Array3<f32> {
    let grain = values(4 * h * w, 9);
    Array3::from_shape_fn((4, h, w), |(c, i, j)| {
        let (y, x) = (i as f32, j as f32);
        let smooth = 0.3 + 0.2 * (x / 23.0 + c as f32).sin() * (y / 17.0).cos();
        let edge = if (x - 90.0).abs() + (y - 60.0).abs() < 30.0 {
            0.3
        } else {
            0.0
        };
        (smooth + edge + 0.1 * (grain[(c * h + i) * w + j] - 0.5)).clamp(0.0, 1.0)
    })
}

/// PSNR (peak 1) between two images.
fn psnr(a: ArrayView3<f32>, b: ArrayView3<f32>) -> f64 {
    let mse = a
        .iter()
        .zip(b.iter())
        .map(|(x, y)| ((x - y) as f64).powi(2))
        .sum::<f64>()
        / a.len() as f64;
    10.0 * (1.0 / mse.max(1e-30)).log10()
}

fn restore_built_in<B: pgrf_nn::ops::PgrfOps>(name: &str, x: ArrayView3<f32>) -> Array3<f32> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../models")
        .join(name);
    let device: B::Device = Default::default();
    let (net, meta) = model::load::<B>(&path, &device).unwrap();
    let r = Restorer::<B>::new(net, meta, SamplerChoice::default(), 0.5, device).unwrap();
    let opts = ImageOptions {
        tile: 256,
        overlap: 64,
        seed: 3,
        noise: Some(NoiseLevel {
            gain: 2e-3,
            floor: 1e-5,
        }),
    };
    restore_image(&r, x, &opts, &pgrf_core::NoProgress).unwrap()
}

/// The built-in SPC and PGRF restore a 176 x 400 packed frame in tiles of
/// 256 on CUDA within 60 dB PSNR of the CPU's result (a difference of 1e-3
/// of white: far below the noise and below one 14-bit DN at x100 gain of
/// the 550D).
#[test]
#[ignore = "needs an NVIDIA GPU"]
fn built_in_models_restore_a_tiled_frame_as_on_the_cpu() {
    let x = scene(176, 400);
    for name in ["spc.safetensors", "pgrf.safetensors"] {
        let cpu = restore_built_in::<Cpu>(name, x.view());
        let gpu = restore_built_in::<Gpu>(name, x.view());
        let p = psnr(cpu.view(), gpu.view());
        let d = cpu
            .iter()
            .zip(gpu.iter())
            .fold(0f32, |m, (a, b)| m.max((a - b).abs()));
        println!("{name}: CUDA vs CPU {p:.1} dB, max |difference| {d:.3e}");
        assert!(p >= 60.0, "{name}: CUDA result {p:.1} dB from the CPU's");
    }
}
