//! Both networks can memorise a single 64x64 synthetic pair: the optimiser,
//! losses and samplers are wired correctly end to end. Bounded step counts,
//! so a regression that slows learning fails rather than hangs.

use burn::module::AutodiffModule;
use burn::optim::AdamConfig;
use burn::tensor::{Tensor, TensorData};
use pgrf_nn::backend::{Cpu, CpuTrain};
use pgrf_nn::data::validation::psnr;
use pgrf_nn::flow::sample::two_stage;
use pgrf_nn::seeded::{materialise, seeded};
use pgrf_nn::step::{denoiser_step, flow_step};
use pgrf_nn::{SidUnetConfig, Sr3Config};
use pgrf_noise::pair::{PairSpec, RatioSpec};
use pgrf_noise::{CameraProfile, ModelKind};
use pgrf_raw::ndarray::Array3;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

const P: usize = 64;

/// A smooth clean image (shading a denoiser can represent exactly) through
/// the real noise model at ISO 1600, ratio 100: the test is about the
/// optimisation and sampling machinery, not about the capacity to memorise
/// texture, so it can finish in seconds.
fn pair() -> (Vec<f32>, Vec<f32>) {
    let mut spec = PairSpec::new(
        CameraProfile::built_in("sony-a7s2").unwrap(),
        ModelKind::Pgrf,
    );
    spec.iso = Some(1600);
    spec.ratio = RatioSpec::Fixed(100.0);
    let clean = Array3::from_shape_fn((4, P, P), |(c, y, x)| {
        let (fy, fx) = (y as f32 / P as f32, x as f32 / P as f32);
        0.35 + 0.2 * (6.0 * fx + c as f32).sin() * (4.0 * fy).cos() + 0.1 * fy
    });
    let p = spec.synthesize(clean.view(), [0, 0, 1, 1], 2024).unwrap();
    let noisy = p.noisy.iter().map(|v| v.clamp(0.0, 1.0)).collect();
    (noisy, p.clean.iter().copied().collect())
}

fn t4<B: burn::tensor::backend::Backend>(v: &[f32], d: &B::Device) -> Tensor<B, 4> {
    Tensor::from_data(TensorData::new(v.to_vec(), [1, 4, P, P]), d)
}

fn out(t: Tensor<Cpu, 4>) -> Vec<f32> {
    t.into_data().to_vec().unwrap()
}

#[test]
fn the_denoiser_memorises_one_pair_past_35_db() {
    let device = Default::default();
    let (noisy, clean) = pair();
    let input_psnr = psnr(&noisy, &clean);
    let mut net = seeded::<CpuTrain, _>(&device, 1, || {
        materialise(
            SidUnetConfig::new()
                .with_width(16)
                .init::<CpuTrain>(&device),
        )
    });
    let mut optim = AdamConfig::new().with_epsilon(1e-8).init();
    let (x, y) = (
        t4::<CpuTrain>(&noisy, &device),
        t4::<CpuTrain>(&clean, &device),
    );
    let mut best = 0.0f32;
    let mut steps = 0;
    // Measured: 35.3 dB after 425 steps (PyTorch, same recipe: 35.2 at 500).
    for step in 0..800 {
        let lr = if step < 600 { 1e-3 } else { 3e-4 };
        net = denoiser_step(net, &mut optim, x.clone(), y.clone(), lr).0;
        steps = step + 1;
        if steps % 25 == 0 {
            let p = psnr(
                &out(net.valid().forward(t4::<Cpu>(&noisy, &device))),
                &clean,
            );
            best = best.max(p);
            if best > 35.0 {
                break;
            }
        }
    }
    eprintln!("denoiser: input {input_psnr:.2} dB -> {best:.2} dB in {steps} steps");
    assert!(best > 35.0, "best {best} dB after {steps} steps");
}

/// Train the small SR3 on the pair (one X0, the one the sampler is evaluated
/// with; t ~ U(0, 1)) until the two-step sample passes `target` dB or
/// `max_steps` run out; returns (best PSNR, steps).
///
/// The literal overfit: learning to generalise over X0 is what real training
/// runs are for; this checks that the flow loss, the path, the time
/// conditioning and the two-stage sampler fit together. The same
/// architecture in PyTorch (bench/train_torch.py, same recipe) climbs just as
/// slowly: 15, 20, 22, 22, 25 dB at 100..500 steps.
fn flow_overfit(max_steps: usize, target: f32) -> (f32, usize) {
    let device = Default::default();
    let (noisy, clean) = pair();
    let cfg = Sr3Config::new()
        .with_inner_channels(16)
        .with_channel_mults(vec![1, 2, 2])
        .with_res_blocks(1)
        .with_attn_levels(vec![])
        .with_norm_groups(8);
    let mut net = seeded::<CpuTrain, _>(&device, 2, || {
        cfg.init::<CpuTrain>(&device).map(materialise)
    })
    .unwrap();
    let mut optim = AdamConfig::new().with_epsilon(1e-8).init();
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(5);
    let (cond, x1) = (
        t4::<CpuTrain>(&noisy, &device),
        t4::<CpuTrain>(&clean, &device),
    );
    let x0_eval: Vec<f32> = (0..4 * P * P)
        .map(|_| StandardNormal.sample(&mut rng))
        .collect();
    let x0 = t4::<CpuTrain>(&x0_eval, &device);
    let sample_psnr = |net: &pgrf_nn::Sr3Unet<CpuTrain>| {
        let v = net.valid();
        let s = two_stage(
            &v,
            t4::<Cpu>(&noisy, &device),
            t4::<Cpu>(&x0_eval, &device),
            0.5,
        );
        psnr(&out(s), &clean)
    };
    let start = sample_psnr(&net);
    let mut best = start;
    let mut steps = 0;
    while steps < max_steps && best <= target {
        let t: f32 = rand::Rng::random(&mut rng);
        let lr = if steps < max_steps * 2 / 3 {
            2e-3
        } else {
            5e-4
        };
        net = flow_step(
            net,
            &mut optim,
            cond.clone(),
            x1.clone(),
            x0.clone(),
            Tensor::from_floats([t], &device),
            lr,
        )
        .0;
        steps += 1;
        if steps % 25 == 0 {
            best = best.max(sample_psnr(&net));
        }
    }
    eprintln!("flow: two-step sample {start:.2} dB untrained -> {best:.2} dB in {steps} steps");
    (best, steps)
}

#[test]
fn the_flow_models_two_step_sample_learns_the_pair() {
    // Bounded for the default suite: measured 18.8 dB at 200 steps.
    let (best, steps) = flow_overfit(200, 16.0);
    assert!(best > 16.0, "best {best} dB after {steps} steps");
}

/// The bar, > 30 dB. Minutes on two CPU cores (burn Flex runs this
/// small network at ~0.3 s a step), so not in the default suite:
/// `cargo test -p pgrf-nn --release --test overfit -- --ignored`.
#[test]
#[ignore]
fn the_flow_models_two_step_sample_memorises_one_pair_past_30_db() {
    let (best, steps) = flow_overfit(6000, 30.0);
    assert!(best > 30.0, "best {best} dB after {steps} steps");
}
