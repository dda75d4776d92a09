//! pgrf's operations against burn's on `Autodiff<Flex>`: forward values and
//! every gradient (input, weight, bias) within 1e-4 of the largest
//! magnitude, on seeded random inputs and a random output weighting `r`
//! (loss `sum(y * r)`); the fused Adam against burn's Adam; a short seeded
//! training run of both networks with either set of operations.

use super::*;
use crate::backend::CpuTrain;
use crate::seeded::{materialise, seeded};
use burn::module::Module;
use burn::nn::conv::{Conv2dConfig, ConvTranspose2dConfig};
use burn::optim::{AdamConfig, GradientsParams, Optimizer};
use burn::tensor::{Distribution, Tensor};

type B = CpuTrain;

fn values<Bk: Backend, const D: usize>(t: Tensor<Bk, D>) -> Vec<f32> {
    t.into_data().convert::<f32>().to_vec().unwrap()
}

/// max |a - b| / max |b|.
fn rel(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len(), "sizes");
    let scale = b.iter().fold(0.0f32, |m, v| m.max(v.abs())).max(1e-12);
    let diff = a
        .iter()
        .zip(b)
        .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()));
    diff / scale
}

fn close(what: &str, a: &[f32], b: &[f32], tol: f32) {
    let r = rel(a, b);
    assert!(r <= tol, "{what}: relative difference {r:e} > {tol:e}");
}

/// Fixed pseudo-random values in [-1, 1) from a hash of the index, not from
/// the backend's generator: a test's two runs must see the same weighting
/// even while other tests draw from that shared generator.
fn pattern(shape: [usize; 4], seed: u64) -> Tensor<B, 4> {
    let len: usize = shape.iter().product();
    let v: Vec<f32> = (0..len as u64)
        .map(|i| {
            let h = (i ^ seed.rotate_left(32)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
            (h >> 40) as f32 / (1u64 << 23) as f32 - 1.0
        })
        .collect();
    Tensor::from_data(burn::tensor::TensorData::new(v, shape), &Default::default())
}

fn random(shape: [usize; 4], seed: u64) -> Tensor<B, 4> {
    seeded::<B, _>(&Default::default(), seed, || {
        Tensor::<B, 4>::random(shape, Distribution::Normal(0.0, 1.0), &Default::default())
    })
}

/// Forward and gradients of `layer` on `x` under `kernels`: (y, dx, dW, db).
/// `track_x` false leaves the input out of the graph (a network's first
/// layer).
fn run_conv<M: Module<B>>(
    m: &M,
    layer: impl Fn(&M, Tensor<B, 4>) -> Tensor<B, 4>,
    params: impl Fn(&M) -> (Tensor<B, 4>, Tensor<B, 1>),
    x: Tensor<B, 4>,
    track_x: bool,
    kernels: Kernels,
) -> [Option<Vec<f32>>; 4] {
    with_kernels(kernels, || {
        let x = if track_x { x.require_grad() } else { x };
        let y = layer(m, x.clone());
        // Offset so that the bias gradient (a sum over every pixel) is far
        // from zero: burn sums in f32, pgrf in f64.
        let r = pattern(y.dims(), 99) + 0.25;
        let grads = (y.clone() * r).sum().backward();
        let (w, b) = params(m);
        [
            Some(values(y)),
            x.grad(&grads).map(values),
            w.grad(&grads).map(values),
            b.grad(&grads).map(values),
        ]
    })
}

fn compare(what: &str, a: [Option<Vec<f32>>; 4], b: [Option<Vec<f32>>; 4]) {
    for (part, (a, b)) in ["forward", "dx", "dW", "db"].iter().zip(a.iter().zip(&b)) {
        match (a, b) {
            (Some(a), Some(b)) => close(&format!("{what} {part}"), a, b, 1e-4),
            (None, None) => {}
            _ => panic!("{what} {part}: a gradient on one side only"),
        }
    }
}

#[test]
fn convolutions_match_burns() {
    let device = Default::default();
    // (cin, cout, kernel, stride, padding, h, w, batch)
    let cases = [
        (3, 5, 3, 1, PaddingConfig2d::Same, 7, 6, 2),
        (4, 6, 3, 1, PaddingConfig2d::Explicit(1, 1, 1, 1), 8, 8, 3),
        (4, 6, 3, 2, PaddingConfig2d::Explicit(1, 1, 1, 1), 9, 8, 2),
        (5, 3, 1, 1, PaddingConfig2d::Valid, 5, 7, 2),
        (2, 3, 3, 1, PaddingConfig2d::Valid, 6, 1 + 4, 1),
        // Wide enough that the forward splits each image into row tiles.
        (32, 8, 3, 1, PaddingConfig2d::Same, 70, 66, 2),
    ];
    for (i, &(cin, cout, k, s, ref pad, h, w, n)) in cases.iter().enumerate() {
        let conv = seeded::<B, _>(&device, 10 + i as u64, || {
            materialise(
                Conv2dConfig::new([cin, cout], [k, k])
                    .with_stride([s, s])
                    .with_padding(pad.clone())
                    .init::<B>(&device),
            )
        });
        let params = |m: &Conv2d<B>| (m.weight.val(), m.bias.as_ref().unwrap().val());
        let x = random([n, cin, h, w], 20 + i as u64);
        for track_x in [true, false] {
            let ours = run_conv(&conv, conv2d, params, x.clone(), track_x, Kernels::Pgrf);
            let burns = run_conv(
                &conv,
                |m, x| m.forward(x),
                params,
                x.clone(),
                track_x,
                Kernels::Pgrf,
            );
            compare(
                &format!("conv case {i} (x tracked: {track_x})"),
                ours,
                burns,
            );
        }
    }
}

/// A large batch: a stride-1 convolution whose weight gradient has more
/// row tiles than it has groups of tiles (partials added in order), and a
/// stride-2 one whose im2col buffer exceeds one chunk, so that its input
/// gradient is computed in chunks of images.
#[test]
fn large_batches_add_up() {
    let device = Default::default();
    // 32 input channels x 9 x 64 x 64 output pixels x 4 B = 4.7 MB per
    // image at stride 2 on 128 x 128; 16 images exceed the 64 MiB budget.
    for (stride, side) in [(1, 64), (2, 128)] {
        let conv = seeded::<B, _>(&device, 5, || {
            materialise(
                Conv2dConfig::new([32, 2], [3, 3])
                    .with_stride([stride, stride])
                    .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                    .init::<B>(&device),
            )
        });
        let params = |m: &Conv2d<B>| (m.weight.val(), m.bias.as_ref().unwrap().val());
        let x = random([16, 32, side, side], 6);
        let ours = run_conv(&conv, conv2d, params, x.clone(), true, Kernels::Pgrf);
        let burns = run_conv(&conv, |m, x| m.forward(x), params, x, true, Kernels::Pgrf);
        compare(&format!("large batch, stride {stride}"), ours, burns);
    }
}

#[test]
fn transposed_convolutions_match_burns() {
    let device = Default::default();
    // (cin, cout, kernel, stride, h, w, batch): the U-Net's 2x2 stride 2
    // (pgrf's tiles of products and shuffles; the third wide enough for two
    // tiles per image), then an overlapping kernel (burn's).
    let cases = [
        (6, 3, 2, 2, 5, 4, 2),
        (4, 4, 2, 2, 1, 3, 1),
        (16, 32, 2, 2, 6, 150, 2),
        (3, 2, 3, 1, 4, 5, 2),
    ];
    for (i, &(cin, cout, k, s, h, w, n)) in cases.iter().enumerate() {
        let up = seeded::<B, _>(&device, 30 + i as u64, || {
            materialise(
                ConvTranspose2dConfig::new([cin, cout], [k, k])
                    .with_stride([s, s])
                    .init::<B>(&device),
            )
        });
        let params = |m: &ConvTranspose2d<B>| (m.weight.val(), m.bias.as_ref().unwrap().val());
        let x = random([n, cin, h, w], 40 + i as u64);
        let ours = run_conv(
            &up,
            conv_transpose2d,
            params,
            x.clone(),
            true,
            Kernels::Pgrf,
        );
        let burns = run_conv(&up, |m, x| m.forward(x), params, x, true, Kernels::Pgrf);
        compare(&format!("transposed case {i}"), ours, burns);
    }
}

/// Activation `f` under `kernels` on `x`: (y, dx).
fn run_act(
    x: Tensor<B, 4>,
    f: impl Fn(Tensor<B, 4>) -> Tensor<B, 4>,
    kernels: Kernels,
) -> [Vec<f32>; 2] {
    with_kernels(kernels, || {
        let x = x.require_grad();
        let y = f(x.clone());
        let r = pattern(y.dims(), 7);
        let grads = (y.clone() * r).sum().backward();
        [values(y), values(x.grad(&grads).unwrap())]
    })
}

#[test]
fn activations_match_burns() {
    // Scaled so that SiLU meets its tails (|x| up to ~40).
    let x = random([2, 3, 17, 19], 8) * 8.0;
    for (name, f) in [
        (
            "leaky_relu",
            (|x| leaky_relu(x, 0.2)) as fn(Tensor<B, 4>) -> Tensor<B, 4>,
        ),
        ("silu", |x| silu(x)),
    ] {
        let [y1, d1] = run_act(x.clone(), f, Kernels::Pgrf);
        let [y2, d2] = run_act(x.clone(), f, Kernels::Burn);
        close(&format!("{name} forward"), &y1, &y2, 1e-4);
        close(&format!("{name} gradient"), &d1, &d2, 1e-4);
    }
}

/// The convolution with its LeakyReLU: fused in one pass on Flex
/// (inference) and two graph nodes under autodiff, both equal to burn's
/// convolution followed by burn's activation within 1e-4, gradients
/// included; on a frame of several row tiles.
#[test]
fn convolution_with_leaky_relu_matches_burns() {
    type Inf = crate::backend::Cpu;
    let device = Default::default();
    let config = Conv2dConfig::new([16, 6], [3, 3]).with_padding(PaddingConfig2d::Same);
    let conv = seeded::<Inf, _>(&device, 31, || materialise(config.init(&device)));
    let x = Tensor::<Inf, 4>::random([2, 16, 40, 70], Distribution::Uniform(-1.0, 1.0), &device);
    let fused = with_kernels(Kernels::Pgrf, || conv2d_leaky(&conv, x.clone(), 0.2));
    let burns = with_kernels(Kernels::Burn, || {
        burn::tensor::activation::leaky_relu(conv.forward(x.clone()), 0.2)
    });
    close("fused forward", &values(fused), &values(burns), 1e-4);

    let conv = seeded::<B, _>(&device, 31, || materialise(config.init(&device)));
    let params = |m: &Conv2d<B>| (m.weight.val(), m.bias.as_ref().unwrap().val());
    let x = random([2, 16, 40, 70], 32);
    let ours = run_conv(
        &conv,
        |m, x| conv2d_leaky(m, x, 0.2),
        params,
        x.clone(),
        true,
        Kernels::Pgrf,
    );
    let burns = run_conv(
        &conv,
        |m, x| burn::tensor::activation::leaky_relu(m.forward(x), 0.2),
        params,
        x,
        true,
        Kernels::Burn,
    );
    compare("conv + leaky relu under autodiff", ours, burns);
}

#[test]
fn kernels_choice_is_per_thread_and_restored() {
    assert_eq!(with_kernels(Kernels::Burn, kernels), Kernels::Burn);
    assert_eq!(
        with_kernels(Kernels::Burn, || with_kernels(Kernels::Pgrf, kernels)),
        Kernels::Pgrf
    );
    assert_eq!(with_kernels(Kernels::Pgrf, kernels), Kernels::Pgrf);
    assert!("cuda".parse::<Kernels>().is_err());
    assert_eq!("burn".parse::<Kernels>(), Ok(Kernels::Burn));
}

/// Five Adam steps on a small network, burn's Adam against pgrf's fused
/// step; then the record written by one continues in the other.
#[test]
fn fused_adam_matches_burns_adam_and_shares_its_records() {
    use burn::optim::adaptor::OptimizerAdaptor;
    use burn::record::{BinBytesRecorder, FullPrecisionSettings, Recorder};
    let device = Default::default();
    let make = || {
        seeded::<B, _>(&device, 50, || {
            materialise(
                Conv2dConfig::new([3, 4], [3, 3])
                    .with_padding(PaddingConfig2d::Same)
                    .init::<B>(&device),
            )
        })
    };
    let x = random([2, 3, 6, 6], 51);
    let grads_of = |m: &Conv2d<B>| {
        let loss = (m.forward(x.clone()) - 0.5).powi_scalar(2).mean();
        GradientsParams::from_grads(loss.backward(), m)
    };
    let mut burn_optim = AdamConfig::new().with_epsilon(1e-8).init::<B, Conv2d<B>>();
    let mut ours = OptimizerAdaptor::<adam::PgrfAdam, Conv2d<B>, B>::from(adam::PgrfAdam::new(
        0.9, 0.999, 1e-8,
    ));
    let (mut a, mut b) = (make(), make());
    for _ in 0..5 {
        a = burn_optim.step(1e-2, a.clone(), grads_of(&a));
        b = with_kernels(Kernels::Pgrf, || ours.step(1e-2, b.clone(), grads_of(&b)));
    }
    close(
        "weights after 5 steps",
        &values(b.weight.val()),
        &values(a.weight.val()),
        1e-5,
    );
    let bias = |m: &Conv2d<B>| values(m.bias.as_ref().unwrap().val());
    close("biases after 5 steps", &bias(&b), &bias(&a), 1e-5);

    // Records: the same bytes layout; burn's record loads into pgrf's Adam.
    let recorder = BinBytesRecorder::<FullPrecisionSettings>::default();
    let burn_bytes = recorder.record(burn_optim.to_record(), ()).unwrap();
    let our_bytes = recorder.record(ours.to_record(), ()).unwrap();
    assert_eq!(burn_bytes.len(), our_bytes.len(), "record sizes");
    let mut resumed = OptimizerAdaptor::<adam::PgrfAdam, Conv2d<B>, B>::from(adam::PgrfAdam::new(
        0.9, 0.999, 1e-8,
    ))
    .load_record(recorder.load(burn_bytes, &device).unwrap());
    let (mut c, mut d) = (a.clone(), a);
    for _ in 0..2 {
        c = burn_optim.step(1e-2, c.clone(), grads_of(&c));
        d = with_kernels(Kernels::Pgrf, || {
            resumed.step(1e-2, d.clone(), grads_of(&d))
        });
    }
    close(
        "weights after resuming",
        &values(d.weight.val()),
        &values(c.weight.val()),
        1e-5,
    );
}

/// A short seeded training run of each network gives the same loss curve
/// with pgrf's operations as with burn's (losses within 1e-3 relative
/// over 8 Adam steps).
#[test]
fn training_curves_match_burns() {
    use crate::arch::sid_unet::SidUnetConfig;
    use crate::arch::sr3::Sr3Config;
    use crate::step::{denoiser_step, flow_step};
    use burn::optim::adaptor::OptimizerAdaptor;
    let device = Default::default();
    let noisy = random([2, 4, 32, 32], 60).clamp(-1.0, 1.0) * 0.5 + 0.5;
    let clean = random([2, 4, 32, 32], 61).clamp(-1.0, 1.0) * 0.25 + 0.5;
    let x0 = random([2, 4, 32, 32], 62);
    let t = Tensor::<B, 1>::from_floats([0.3, 0.8], &device);
    // Each network is drawn once; both runs start from the same copy.
    let sr3 = seeded::<B, _>(&device, 63, || {
        materialise(
            Sr3Config::new()
                .with_inner_channels(8)
                .with_channel_mults(vec![1, 2])
                .with_res_blocks(1)
                .with_attn_levels(vec![1])
                .with_norm_groups(4)
                .init::<B>(&device)
                .unwrap(),
        )
    });
    let unet = seeded::<B, _>(&device, 64, || {
        materialise(SidUnetConfig::new().with_width(4).init::<B>(&device))
    });
    let curve = |kernels: Kernels, flow: bool| {
        with_kernels(kernels, || {
            let adam = || adam::PgrfAdam::new(0.9, 0.999, 1e-8);
            let mut losses = Vec::new();
            if flow {
                let mut net = sr3.clone();
                let mut optim = OptimizerAdaptor::<_, _, B>::from(adam());
                for _ in 0..8 {
                    let (n, l) = flow_step(
                        net,
                        &mut optim,
                        noisy.clone(),
                        clean.clone(),
                        x0.clone(),
                        t.clone(),
                        3e-3,
                    );
                    net = n;
                    losses.push(l);
                }
            } else {
                let mut net = unet.clone();
                let mut optim = OptimizerAdaptor::<_, _, B>::from(adam());
                for _ in 0..8 {
                    let (n, l) = denoiser_step(net, &mut optim, noisy.clone(), clean.clone(), 3e-3);
                    net = n;
                    losses.push(l);
                }
            }
            losses
        })
    };
    for flow in [false, true] {
        let (ours, burns) = (curve(Kernels::Pgrf, flow), curve(Kernels::Burn, flow));
        assert!(ours[7] < ours[0], "the run learns: {ours:?}");
        close(&format!("loss curve (flow: {flow})"), &ours, &burns, 1e-3);
    }
}

/// A GroupNorm of `groups` x `channels` with its scale and shift moved
/// away from burn's (1, 0) initialisation by `step` per value from `from`.
fn shifted_group_norm(groups: usize, channels: usize, step: f32, from: f32) -> GroupNorm<B> {
    let device = Default::default();
    let gn = burn::nn::GroupNormConfig::new(groups, channels).init::<B>(&device);
    let mut named = crate::named::collect::<B, _>(&gn);
    for t in named.values_mut() {
        for (i, v) in t.values.iter_mut().enumerate() {
            *v += step * i as f32 + from;
        }
    }
    crate::named::assign(gn, &named, &device).unwrap()
}

/// `norm` on `x` against `reference` on it: the outputs, the input's and
/// the affine's gradients (loss `sum(y * pattern)`), each within 1e-4.
fn norms_agree(
    what: &str,
    gn: &GroupNorm<B>,
    x: &Tensor<B, 4>,
    norm: impl Fn(Tensor<B, 4>) -> Tensor<B, 4>,
    reference: impl Fn(Tensor<B, 4>) -> Tensor<B, 4>,
) {
    let run = |f: &dyn Fn(Tensor<B, 4>) -> Tensor<B, 4>| {
        let x = x.clone().require_grad();
        let y = f(x.clone());
        let grads = (y.clone() * pattern(y.dims(), 71)).sum().backward();
        let gamma = gn.gamma.as_ref().unwrap().val().grad(&grads).map(values);
        let beta = gn.beta.as_ref().unwrap().val().grad(&grads).map(values);
        [
            values(y),
            values(x.grad(&grads).unwrap()),
            gamma.unwrap(),
            beta.unwrap(),
        ]
    };
    let (ours, burns) = (run(&norm), run(&reference));
    for (part, (a, b)) in ["forward", "dx", "dgamma", "dbeta"]
        .iter()
        .zip(ours.iter().zip(&burns))
    {
        close(&format!("{what}: {part}"), a, b, 1e-4);
    }
}

#[test]
fn group_norm_matches_burns() {
    let gn = shifted_group_norm(4, 12, 0.1, -0.4);
    let x = random([3, 12, 5, 7], 70) * 3.0 + 1.0;
    norms_agree(
        "group norm",
        &gn,
        &x,
        |x| group_norm(&gn, x),
        |x| gn.forward(x),
    );
}

/// The kernels' windows taken in place equal burn's GroupNorm run on the
/// windows cut out as batch items ([`crate::norm::windowed`]), forward and
/// every gradient, with and without the SiLU after it; an input that is not
/// a whole number of windows is normalised whole by both.
#[test]
fn windowed_group_norm_matches_burns_on_cut_windows() {
    let gn = shifted_group_norm(4, 8, 0.15, -0.5);
    for (dims, window, then_silu) in [
        ([2, 8, 8, 12], 4, false),
        ([1, 8, 16, 8], 8, true),
        ([2, 8, 9, 12], 4, true),
    ] {
        let x = random(dims, 72) * 2.0 - 0.5;
        let reference = |x: Tensor<B, 4>| {
            let y = crate::norm::windowed(x, window, |t| gn.forward(t));
            if then_silu {
                burn::tensor::activation::silu(y)
            } else {
                y
            }
        };
        norms_agree(
            &format!("{dims:?} window {window}, SiLU {then_silu}"),
            &gn,
            &x,
            |x| group_norm_windowed(&gn, x, window, then_silu),
            reference,
        );
    }
}

/// Inference's blended windows (`NormSpec::blend`): the kernels' forward on
/// Flex equals [`crate::norm::blended`] in burn's operations (the path of
/// backends without pgrf's kernels), and `group_norm_windowed` takes either
/// path to the same result, with and without the SiLU after it; both move
/// the pixels away from the windows normalised on their own, which a
/// recorded (training) pass keeps on either path; an input of one window is
/// plain GroupNorm.
#[test]
fn blended_windows_agree_between_the_kernels_and_burns_operations() {
    type I = <B as burn::tensor::backend::AutodiffBackend>::InnerBackend;
    let gn = burn::module::AutodiffModule::valid(&shifted_group_norm(4, 8, 0.15, -0.5));
    for (dims, window, then_silu) in [([2, 8, 32, 48], 16, false), ([1, 8, 48, 32], 16, true)] {
        let x = (random(dims, 73) * 2.0 - 0.5).inner();
        let ours = values(group_norm_windowed::<I>(&gn, x.clone(), window, then_silu));
        let act = |t: Tensor<I, 4>| {
            if then_silu {
                burn::tensor::activation::silu(t)
            } else {
                t
            }
        };
        let affine = (
            gn.gamma.as_ref().map(|g| g.val()),
            gn.beta.as_ref().map(|b| b.val()),
        );
        let parts = (gn.num_groups, gn.epsilon);
        let burns = crate::norm::blended(x.clone(), affine.0, affine.1, parts, window);
        let burns = values(act(burns));
        close(&format!("{dims:?} window {window}"), &ours, &burns, 1e-4);
        let by_burn = with_kernels(Kernels::Burn, || {
            values(group_norm_windowed::<I>(&gn, x.clone(), window, then_silu))
        });
        close(&format!("{dims:?}: burn's path"), &by_burn, &burns, 1e-5);
        let recorded = |k| {
            let tracked = shifted_group_norm(4, 8, 0.15, -0.5);
            let x = Tensor::<B, 4>::from_inner(x.clone()).require_grad();
            with_kernels(k, || {
                values(group_norm_windowed(&tracked, x, window, then_silu))
            })
        };
        let apart = values(act(crate::norm::windowed(x.clone(), window, |t| {
            gn.forward(t)
        })));
        assert!(
            rel(&ours, &apart) > 1e-2,
            "{dims:?}: blending changed nothing"
        );
        for k in [Kernels::Pgrf, Kernels::Burn] {
            close(
                &format!("{dims:?}: recorded, {k:?}"),
                &recorded(k),
                &apart,
                1e-4,
            );
        }
    }
    let x = random([1, 8, 16, 16], 74).inner();
    let one = values(group_norm_windowed::<I>(&gn, x.clone(), 16, false));
    close("one window", &one, &values(gn.forward(x)), 1e-5);
}
