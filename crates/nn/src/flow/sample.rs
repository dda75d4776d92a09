//! Samplers of the rectified flow: how a trained velocity field v turns a
//! start X0 ~ N(0, I) into an image, given the condition T (the noisy
//! capture).
//!
//! The paper's point is two network evaluations instead of hundreds
//! (eq. 4.10-4.12):
//!
//! - eq. 4.10, the first stage (`first_stage`, crate-internal):
//!   XZ = v(X0, T, 0) + X0 jumps straight from the start to a first estimate
//!   of X1 (a single Euler step over the whole path); on its own it is the
//!   one-step sampler;
//! - eq. 4.11, inside the second stage (`second_stage`, crate-internal):
//!   Xt2 = t2 XZ + (1 - t2) X0 re-enters the straight path (eq. 4.1,
//!   [`super::interpolate`]) at the searched time t2;
//! - eq. 4.12, the second stage: XM = v(Xt2, T, t2) + X0 is the result.
//!
//! [`two_stage`] chains the two; the sampling search (Algorithm 2,
//! `pgrf_app::search`) runs the first stage once per pair and the second
//! once per candidate t, so it evaluates exactly what the sampler does at
//! t2 = t. Euler integration of dX/dt = v(X, T, t) is kept for comparison
//! ([`Sampler::Euler`]).
//!
//! Public: [`two_stage`], the [`Velocity`] trait it samples, and the
//! sampler a user picks ([`SamplerKind`], resolved to a [`Sampler`] by
//! [`crate::infer::Restorer`]).

use super::path::interpolate;
use crate::arch::sr3::Sr3Unet;
use crate::condition::{Conditioned, Conditioning, NoiseLevel};
use crate::ops::PgrfOps;
use burn::tensor::Tensor;
use pgrf_core::parse::ParseError;

/// A velocity field v(X, T, t) (the paper's v, an SR3-style U-Net with the
/// condition T concatenated to its input). The samplers are written against
/// this so that their arithmetic can be checked on fields with closed forms.
pub trait Velocity<B: PgrfOps> {
    /// v(X, T, t) for a batch: `x` and `cond` `(n, c, h, w)`, `t` `(n)`.
    fn velocity(&self, x: Tensor<B, 4>, cond: Tensor<B, 4>, t: Tensor<B, 1>) -> Tensor<B, 4>;

    /// How the field is told its condition's noise level (the condition
    /// the samplers pass is the conditioned one, [`crate::condition`]).
    fn conditioning(&self) -> Conditioning {
        Conditioning::None
    }

    /// Whether the field reads T's values below black as recorded (else
    /// its callers clamp T at 0: `arch::input_as_read`).
    fn keeps_below_black(&self) -> bool {
        false
    }

    /// The condition the samplers pass, from the prepared batch `c` and
    /// the capture `noisy` as handed over (clipped at white only; item i at
    /// `levels[i]`): `c`'s input, unless the field also reads a prior's
    /// restoration ([`Sr3Unet::condition`]).
    fn condition(
        &self,
        c: &Conditioned<B>,
        _noisy: Tensor<B, 4>,
        _levels: &[NoiseLevel],
    ) -> Tensor<B, 4> {
        c.input.clone()
    }
}

impl<B: PgrfOps> Velocity<B> for Sr3Unet<B> {
    fn velocity(&self, x: Tensor<B, 4>, cond: Tensor<B, 4>, t: Tensor<B, 1>) -> Tensor<B, 4> {
        self.forward(x, cond, t)
    }

    fn conditioning(&self) -> Conditioning {
        Sr3Unet::conditioning(self)
    }

    fn keeps_below_black(&self) -> bool {
        Sr3Unet::keeps_below_black(self)
    }

    fn condition(
        &self,
        c: &Conditioned<B>,
        noisy: Tensor<B, 4>,
        levels: &[NoiseLevel],
    ) -> Tensor<B, 4> {
        Sr3Unet::condition(self, c, noisy, levels)
    }
}

/// The time `t` for each of `n` batch items.
fn times<B: PgrfOps>(n: usize, t: f32, device: &B::Device) -> Tensor<B, 1> {
    Tensor::<B, 1>::full([n], t, device)
}

/// First stage, eq. 4.10: XZ = v(X0, T, 0) + X0 (`cond` is T, `x0` is X0).
/// Also the whole one-step sampler.
pub fn first_stage<B: PgrfOps>(
    net: &impl Velocity<B>,
    cond: Tensor<B, 4>,
    x0: Tensor<B, 4>,
) -> Tensor<B, 4> {
    let n = x0.dims()[0];
    let device = x0.device();
    net.velocity(x0.clone(), cond, times::<B>(n, 0.0, &device)) + x0
}

/// Second stage, eq. 4.11-4.12: Xt2 = t2 XZ + (1 - t2) X0 (eq. 4.1 at t2),
/// then XM = v(Xt2, T, t2) + X0. `xz` is the first stage's XZ.
pub fn second_stage<B: PgrfOps>(
    net: &impl Velocity<B>,
    cond: Tensor<B, 4>,
    x0: Tensor<B, 4>,
    xz: Tensor<B, 4>,
    t2: f32,
) -> Tensor<B, 4> {
    let n = x0.dims()[0];
    let t = times::<B>(n, t2, &x0.device());
    let xt2 = interpolate(xz, x0.clone(), t.clone());
    net.velocity(xt2, cond, t) + x0
}

/// The paper's two-stage sampler (eq. 4.10-4.12) with second time `t2`:
/// XM = v(t2 XZ + (1 - t2) X0, T, t2) + X0, XZ = v(X0, T, 0) + X0.
/// `cond` is T and `x0` is X0, both `(n, 4, h, w)`; `t2` in [0, 1]. Returns
/// XM, the restored batch (not clamped), same shape.
pub fn two_stage<B: PgrfOps>(
    net: &impl Velocity<B>,
    cond: Tensor<B, 4>,
    x0: Tensor<B, 4>,
    t2: f32,
) -> Tensor<B, 4> {
    let xz = first_stage(net, cond.clone(), x0.clone());
    second_stage(net, cond, x0, xz, t2)
}

/// One network evaluation: XZ = X0 + v(X0, T, 0) (the first stage alone).
pub fn one_step<B: PgrfOps>(
    net: &impl Velocity<B>,
    cond: Tensor<B, 4>,
    x0: Tensor<B, 4>,
) -> Tensor<B, 4> {
    first_stage(net, cond, x0)
}

/// Euler integration of dX/dt = v(X, T, t) from X0 at t = 0 to t = 1 in
/// `steps` steps (the many-step baseline the two-stage sampler replaces).
pub(crate) fn euler<B: PgrfOps>(
    net: &impl Velocity<B>,
    cond: Tensor<B, 4>,
    x0: Tensor<B, 4>,
    steps: usize,
) -> Tensor<B, 4> {
    let n = x0.dims()[0];
    let device = x0.device();
    let dt = 1.0 / steps.max(1) as f32;
    let mut x = x0;
    for i in 0..steps.max(1) {
        let v = net.velocity(
            x.clone(),
            cond.clone(),
            times::<B>(n, i as f32 * dt, &device),
        );
        x = x + v * dt;
    }
    x
}

/// How a flow model turns its start X0 into an image; the denoiser ignores it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Sampler {
    /// The paper's sampler: two evaluations, second at time `t2`.
    TwoStage {
        /// The second stage's time t2 in [0, 1] (the file's searched value
        /// unless overridden).
        t2: f32,
    },
    /// One evaluation (the first stage alone).
    OneStep,
    /// Euler integration with `steps` evaluations.
    Euler {
        /// Steps of equal length from t = 0 to 1 (at least 1).
        steps: usize,
    },
}

impl Sampler {
    /// Network evaluations per sample (the cost the paper compares).
    pub(crate) fn nfe(&self) -> usize {
        match self {
            Sampler::TwoStage { .. } => 2,
            Sampler::OneStep => 1,
            Sampler::Euler { steps } => (*steps).max(1),
        }
    }

    /// The restored batch from condition T `cond` and start X0 `x0`, both
    /// `(n, 4, h, w)`.
    pub(crate) fn run<B: PgrfOps>(
        &self,
        net: &impl Velocity<B>,
        cond: Tensor<B, 4>,
        x0: Tensor<B, 4>,
    ) -> Tensor<B, 4> {
        match *self {
            Sampler::TwoStage { t2 } => two_stage(net, cond, x0, t2),
            Sampler::OneStep => one_step(net, cond, x0),
            Sampler::Euler { steps } => euler(net, cond, x0, steps),
        }
    }
}

impl std::fmt::Display for Sampler {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Sampler::TwoStage { t2 } => write!(f, "two-stage (t2 = {t2})"),
            Sampler::OneStep => f.write_str("one-step"),
            Sampler::Euler { steps } => write!(f, "euler-{steps}"),
        }
    }
}

/// The kind of sampler a user names; the two-stage one takes its t2 from
/// the weight file unless told otherwise, so it is resolved later.
/// Parsed from `two-stage`, `one-step` or `euler:N` (case-insensitive; `2`,
/// `1` and `euler-N` also work).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SamplerKind {
    /// The paper's two-stage sampler ([`Sampler::TwoStage`]).
    TwoStage,
    /// The first stage alone ([`Sampler::OneStep`]).
    OneStep,
    /// Euler integration with this many steps, 1 to 10000
    /// ([`Sampler::Euler`]).
    Euler(usize),
}

impl std::str::FromStr for SamplerKind {
    type Err = ParseError;
    fn from_str(s: &str) -> Result<Self, ParseError> {
        let lower = s.to_ascii_lowercase();
        match lower.as_str() {
            "two-stage" | "twostage" | "2" => return Ok(Self::TwoStage),
            "one-step" | "onestep" | "1" => return Ok(Self::OneStep),
            _ => {}
        }
        // One separator at most: `euler:-5` is a negative count, not 5.
        let n = lower
            .strip_prefix("euler")
            .map(|r| r.strip_prefix([':', '-']).unwrap_or(r))
            .ok_or_else(|| {
                ParseError::unknown_name(
                    s,
                    format!("unknown sampler '{s}' (expected two-stage, one-step or euler:N)"),
                )
            })?;
        match n.parse::<usize>() {
            Ok(n) if (1..=10_000).contains(&n) => Ok(Self::Euler(n)),
            _ => Err(ParseError::out_of_range(
                s,
                format!("sampler '{s}': Euler needs a step count from 1 to 10000, e.g. euler:50"),
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arch::sr3::Sr3Config;
    use crate::backend::Cpu;
    use burn::module::{Module, Param};
    use burn::tensor::{Tensor, TensorData};

    #[test]
    fn sampler_names_parse() {
        assert_eq!("two-stage".parse(), Ok(SamplerKind::TwoStage));
        assert_eq!("one-step".parse(), Ok(SamplerKind::OneStep));
        assert_eq!("euler:50".parse(), Ok(SamplerKind::Euler(50)));
        assert_eq!("Euler-8".parse(), Ok(SamplerKind::Euler(8)));
        assert!("euler:0".parse::<SamplerKind>().is_err());
        // A sign is not a separator (issue 37: euler:-5 ran as euler:5).
        for bad in ["euler:-5", "euler--5", "euler::5", "euler:", "euler:10001"] {
            let e = bad.parse::<SamplerKind>().unwrap_err().to_string();
            assert!(e.contains("from 1 to 10000"), "{bad}: {e}");
        }
        assert_eq!("euler5".parse(), Ok(SamplerKind::Euler(5)));
        assert!("heun".parse::<SamplerKind>().is_err());
        assert_eq!(Sampler::Euler { steps: 50 }.nfe(), 50);
        assert_eq!(Sampler::TwoStage { t2: 0.3 }.nfe(), 2);
    }

    /// v(X, T, t) = a X + c T + d t, elementwise: closed forms by hand.
    struct Linear {
        a: f32,
        c: f32,
        d: f32,
    }
    impl Velocity<Cpu> for Linear {
        fn velocity(
            &self,
            x: Tensor<Cpu, 4>,
            cond: Tensor<Cpu, 4>,
            t: Tensor<Cpu, 1>,
        ) -> Tensor<Cpu, 4> {
            let [n, ch, h, w] = x.dims();
            let tt = t.reshape([n, 1, 1, 1]).expand([n, ch, h, w]);
            x * self.a + cond * self.c + tt * self.d
        }
    }

    fn scalar(s: &Sampler, f: &Linear, x0: f32, cond: f32) -> f32 {
        let dev = Default::default();
        let x = Tensor::<Cpu, 4>::full([1, 1, 1, 1], x0, &dev);
        let c = Tensor::<Cpu, 4>::full([1, 1, 1, 1], cond, &dev);
        s.run(f, c, x).into_scalar()
    }

    #[test]
    fn two_stage_sampler_matches_a_hand_computed_result() {
        // a = 0.5, c = 2, d = -1, X0 = 0.2, T = 0.3, t2 = 0.6:
        // XZ  = v(0.2, 0.3, 0) + 0.2 = 0.1 + 0.6 + 0 + 0.2   = 0.9
        // Xt2 = 0.6 * 0.9 + 0.4 * 0.2                         = 0.62
        // XM  = v(0.62, 0.3, 0.6) + 0.2 = 0.31 + 0.6 - 0.6 + 0.2 = 0.51
        let f = Linear {
            a: 0.5,
            c: 2.0,
            d: -1.0,
        };
        let got = scalar(&Sampler::TwoStage { t2: 0.6 }, &f, 0.2, 0.3);
        assert!((got - 0.51).abs() < 1e-6, "{got}");
        // One step: XZ = 0.9.
        let got = scalar(&Sampler::OneStep, &f, 0.2, 0.3);
        assert!((got - 0.9).abs() < 1e-6, "{got}");
        // Euler, 2 steps of 0.5: x1 = 0.2 + 0.5 (0.1 + 0.6) = 0.55;
        // x2 = 0.55 + 0.5 (0.275 + 0.6 - 0.5) = 0.7375.
        let got = scalar(&Sampler::Euler { steps: 2 }, &f, 0.2, 0.3);
        assert!((got - 0.7375).abs() < 1e-6, "{got}");
    }

    /// A velocity field whose every weight is zero except the output
    /// convolution's bias b: v(X, T, t) = b everywhere, whatever X, T, t.
    /// The samplers then have closed forms to check against by hand:
    /// two-stage XM = X0 + b (the second evaluation starts from
    /// Xt2 = t2 (X0 + b) + (1 - t2) X0 but v ignores it), one-step X0 + b,
    /// Euler-N X0 + N * b / N.
    fn constant_field(b: [f32; 4]) -> Sr3Unet<Cpu> {
        let cfg = Sr3Config::new()
            .with_inner_channels(8)
            .with_channel_mults(vec![1, 2])
            .with_res_blocks(1)
            .with_attn_levels(vec![])
            .with_norm_groups(4);
        let dev = Default::default();
        let net = cfg.init::<Cpu>(&dev).unwrap();
        let zeroed = net.map(&mut Zero);
        let mut tensors = crate::named::collect(&zeroed);
        let bias = tensors
            .get_mut("final_conv.bias")
            .expect("the output convolution's bias");
        assert_eq!(bias.shape, vec![4]);
        bias.values = b.to_vec();
        crate::named::assign(zeroed, &tensors, &dev).unwrap()
    }

    struct Zero;
    impl burn::module::ModuleMapper<Cpu> for Zero {
        fn map_float<const D: usize>(
            &mut self,
            param: Param<Tensor<Cpu, D>>,
        ) -> Param<Tensor<Cpu, D>> {
            param.map(|t| t.zeros_like())
        }
    }

    /// The real SR3 network with fixed weights, through the same samplers.
    #[test]
    fn samplers_on_an_sr3_network_with_fixed_weights() {
        let b = [0.25f32, -0.5, 0.125, 1.0];
        let net = constant_field(b);
        let dev = Default::default();
        let x0v: Vec<f32> = (0..4 * 4 * 4).map(|i| (i as f32 * 0.37).sin()).collect();
        let x0 = Tensor::<Cpu, 4>::from_data(TensorData::new(x0v.clone(), [1, 4, 4, 4]), &dev);
        let cond = Tensor::<Cpu, 4>::ones([1, 4, 4, 4], &dev) * 0.3;
        let expect: Vec<f32> = x0v.iter().enumerate().map(|(i, v)| v + b[i / 16]).collect();
        for s in [
            Sampler::TwoStage { t2: 0.4 },
            Sampler::OneStep,
            Sampler::Euler { steps: 4 },
        ] {
            let out: Vec<f32> = s
                .run(&net, cond.clone(), x0.clone())
                .into_data()
                .to_vec()
                .unwrap();
            for (o, e) in out.iter().zip(&expect) {
                assert!((o - e).abs() < 1e-6, "{s}: {o} vs {e}");
            }
        }
    }
}
