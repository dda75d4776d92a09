//! pgrf's own training operations, added to burn 0.21 as a backend
//! extension: a trait of ours ([`PgrfOps`]) whose defaults are burn's own
//! operations, implemented with pgrf's kernels (`pgrf_kernels`) for the Flex
//! CPU backend (module `flex`) and with graph nodes of their own (`Backward`) for
//! the autodiff backend (module `autodiff`); the CUDA backend keeps every
//! default.
//!
//! Why: on the CPU, burn's Flex backend leaves a training step 2.6-2.9x
//! behind PyTorch (BENCHMARKS.md, "Training step"). Its convolution weight
//! gradient is a forward convolution over strided views, its bias gradient a
//! copy of the whole output gradient, its input gradient a serial scatter,
//! and activations and Adam run as many full-size passes. Here the weight
//! and input gradients are matrix products over im2col tiles, the 2x2
//! transposed convolution is a product and a shuffle, activations are one
//! pass forward and one backward, GroupNorm a few passes per (image, group)
//! block, and Adam one pass per parameter
//! tensor ([`adam::PgrfAdam`]). The convolution is pgrf's forward and
//! backward (`pgrf_kernels::conv_forward` and `conv_backward`: im2col over
//! cache-sized row tiles, one gemm product each; the weight gradient summed
//! over the tiles in a fixed order, the stride-1 input gradient a forward
//! convolution by the flipped kernel), with LeakyReLU fused into the
//! forward's tiles at inference (BENCHMARKS.md, issue 38).
//!
//! The networks call the layer functions here ([`conv2d`], [`conv2d_leaky`],
//! [`conv_transpose2d`], [`leaky_relu`], [`silu`], [`group_norm`]) instead of the modules'
//! `forward`; parameters, records and weight files are burn's modules
//! unchanged. The configuration of a call that runs a network (training's
//! `TrainConfig::kernels`, inference's `Tiling::kernels`, the search's
//! options) chooses between these operations ([`Kernels::Pgrf`], the
//! default) and burn's ([`Kernels::Burn`], for comparison), and the call
//! runs inside [`with_kernels`]: with `Burn` the layer functions build
//! exactly the graph `forward` built before.

pub mod adam;
mod autodiff;
mod flex;
#[cfg(test)]
mod tests;

use burn::nn::conv::{Conv2d, ConvTranspose2d};
use burn::nn::{GroupNorm, PaddingConfig2d};
use burn::tensor::backend::{AutodiffBackend, Backend};
use burn::tensor::ops::{ConvOptions, ConvTransposeOptions, FloatTensor};
use burn::tensor::{Tensor, TensorPrimitive};

pub use pgrf_kernels::adam::AdamStep;

/// Whose operations the CPU backend runs: pgrf's kernels (the default) or
/// burn's.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Kernels {
    /// pgrf's operations (the default).
    #[default]
    Pgrf,
    /// burn 0.21's own operations, as before pgrf had its own.
    Burn,
}

impl std::str::FromStr for Kernels {
    type Err = pgrf_core::parse::ParseError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "pgrf" => Ok(Self::Pgrf),
            "burn" => Ok(Self::Burn),
            _ => Err(pgrf_core::parse::ParseError::unknown_name(
                s,
                format!("unknown kernels '{s}' (expected pgrf or burn)"),
            )),
        }
    }
}

impl std::fmt::Display for Kernels {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Pgrf => "pgrf",
            Self::Burn => "burn",
        })
    }
}

thread_local! {
    /// A choice for the current thread only ([`with_kernels`]).
    static THREAD_KERNELS: std::cell::Cell<Option<Kernels>> = const { std::cell::Cell::new(None) };
}

/// Run `f` with `k` chosen on the current thread: the graphs `f` builds and
/// the optimiser steps it takes on this thread (where every network runs:
/// the training loop, the tiles of a restoration) use `k`'s operations.
/// Read when a layer builds its part of the graph; the backward follows
/// what the forward chose.
pub fn with_kernels<R>(k: Kernels, f: impl FnOnce() -> R) -> R {
    struct Restore(Option<Kernels>);
    impl Drop for Restore {
        fn drop(&mut self) {
            THREAD_KERNELS.with(|c| c.set(self.0));
        }
    }
    let _restore = Restore(THREAD_KERNELS.with(|c| c.replace(Some(k))));
    f()
}

/// The operations in force on this thread: [`with_kernels`]'s choice
/// inside it, else pgrf's.
pub fn kernels() -> Kernels {
    THREAD_KERNELS.with(|c| c.get()).unwrap_or_default()
}

/// Which gradients a backward pass has to produce (the parents that need
/// one); the others are not computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Needed {
    /// The input's.
    pub x: bool,
    /// The weight's.
    pub weight: bool,
    /// The bias's.
    pub bias: bool,
}

/// Gradients of a convolution's input, weight and bias (`None` where not
/// [`Needed`]).
pub struct ConvGrads<B: Backend> {
    /// Of the input.
    pub x: Option<FloatTensor<B>>,
    /// Of the weight.
    pub weight: Option<FloatTensor<B>>,
    /// Of the bias.
    pub bias: Option<FloatTensor<B>>,
}

/// pgrf's operations on a backend. Every method has burn's operation as its
/// default, so a backend without kernels of its own (CUDA) runs exactly
/// what burn runs; the layer functions only take pgrf's path where
/// [`PgrfOps::pgrf_kernels`] says so.
pub trait PgrfOps: Backend {
    /// Whether the layer functions use the `pgrf_*` operations on this
    /// backend (false: the modules' own `forward`).
    fn pgrf_kernels() -> bool {
        false
    }

    /// 2-D convolution, the graph node whose backward is
    /// [`PgrfOps::pgrf_conv2d_backward`].
    fn pgrf_conv2d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: Option<FloatTensor<Self>>,
        options: ConvOptions<2>,
    ) -> FloatTensor<Self> {
        Self::conv2d(x, weight, bias, options)
    }

    /// [`PgrfOps::pgrf_conv2d`] followed by [`PgrfOps::pgrf_leaky_relu`]:
    /// two graph nodes by default (so autodiff keeps the pre-activation),
    /// one fused pass where a backend without autodiff has it.
    fn pgrf_conv2d_leaky(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: Option<FloatTensor<Self>>,
        options: ConvOptions<2>,
        slope: f32,
    ) -> FloatTensor<Self> {
        Self::pgrf_leaky_relu(Self::pgrf_conv2d(x, weight, bias, options), slope)
    }

    /// Gradients of [`PgrfOps::pgrf_conv2d`] from its inputs and output
    /// gradient `dy`.
    fn pgrf_conv2d_backward(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: Option<FloatTensor<Self>>,
        dy: FloatTensor<Self>,
        options: ConvOptions<2>,
        needed: Needed,
    ) -> ConvGrads<Self> {
        burn_conv2d_backward::<Self>(x, weight, bias, dy, options, needed)
    }

    /// 2-D transposed convolution, the graph node whose backward is
    /// [`PgrfOps::pgrf_conv_transpose2d_backward`].
    fn pgrf_conv_transpose2d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: Option<FloatTensor<Self>>,
        options: ConvTransposeOptions<2>,
    ) -> FloatTensor<Self> {
        Self::conv_transpose2d(x, weight, bias, options)
    }

    /// Gradients of [`PgrfOps::pgrf_conv_transpose2d`].
    fn pgrf_conv_transpose2d_backward(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: Option<FloatTensor<Self>>,
        dy: FloatTensor<Self>,
        options: ConvTransposeOptions<2>,
        needed: Needed,
    ) -> ConvGrads<Self> {
        burn_conv_transpose2d_backward::<Self>(x, weight, bias, dy, options, needed)
    }

    /// LeakyReLU with `slope` below zero.
    fn pgrf_leaky_relu(x: FloatTensor<Self>, slope: f32) -> FloatTensor<Self> {
        Self::leaky_relu(x, slope.into())
    }

    /// LeakyReLU's input gradient from its input and output gradient.
    fn pgrf_leaky_relu_backward(
        x: FloatTensor<Self>,
        dy: FloatTensor<Self>,
        slope: f32,
    ) -> FloatTensor<Self> {
        burn_leaky_relu_backward::<Self>(x, dy, slope)
    }

    /// SiLU, `x * sigmoid(x)`.
    fn pgrf_silu(x: FloatTensor<Self>) -> FloatTensor<Self> {
        burn_silu::<Self>(x)
    }

    /// SiLU's input gradient, `dy * s * (1 + x (1 - s))` with `s =
    /// sigmoid(x)`.
    fn pgrf_silu_backward(x: FloatTensor<Self>, dy: FloatTensor<Self>) -> FloatTensor<Self> {
        burn_silu_backward::<Self>(x, dy)
    }

    /// GroupNorm of `x` as `spec` says, with its affine `gamma`, `beta`.
    fn pgrf_group_norm(
        x: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        spec: NormSpec,
    ) -> FloatTensor<Self> {
        burn_group_norm::<Self>(x, gamma, beta, spec)
    }

    /// Gradients of [`PgrfOps::pgrf_group_norm`]: `[dx, dgamma, dbeta]`.
    fn pgrf_group_norm_backward(
        x: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        dy: FloatTensor<Self>,
        spec: NormSpec,
    ) -> [FloatTensor<Self>; 3] {
        burn_group_norm_backward::<Self>(x, gamma, dy, spec)
    }

    /// One Adam step on one parameter tensor: returns the parameter and the
    /// two moments after the update (`m`, `v` absent on the first step).
    /// The arithmetic of `pgrf_kernels::adam::adam`.
    fn pgrf_adam(
        param: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        m: Option<FloatTensor<Self>>,
        v: Option<FloatTensor<Self>>,
        step: AdamStep,
    ) -> [FloatTensor<Self>; 3] {
        burn_adam::<Self>(param, grad, m, v, step)
    }
}

/// LeakyReLU's input gradient in burn's tensor operations.
pub(crate) fn burn_leaky_relu_backward<B: Backend>(
    x: FloatTensor<B>,
    dy: FloatTensor<B>,
    slope: f32,
) -> FloatTensor<B> {
    let settings = burn::tensor::get_device_settings::<B>(&B::float_device(&x));
    let mask = B::float_lower_elem(x, 0f32.into(), settings.bool_dtype);
    let scaled = B::float_mul_scalar(dy.clone(), slope.into());
    B::float_mask_where(dy, mask, scaled)
}

/// SiLU in burn's tensor operations, `x * sigmoid(x)`.
pub(crate) fn burn_silu<B: Backend>(x: FloatTensor<B>) -> FloatTensor<B> {
    B::float_mul(x.clone(), B::sigmoid(x))
}

/// SiLU's input gradient in burn's tensor operations.
pub(crate) fn burn_silu_backward<B: Backend>(
    x: FloatTensor<B>,
    dy: FloatTensor<B>,
) -> FloatTensor<B> {
    let s = B::sigmoid(x.clone());
    let one_minus = B::float_add_scalar(B::float_neg(s.clone()), 1f32.into());
    let inner = B::float_add_scalar(B::float_mul(x, one_minus), 1f32.into());
    B::float_mul(dy, B::float_mul(s, inner))
}

/// GroupNorm in burn's tensor operations (pgrf's folded form,
/// [`crate::norm`]), each window cut out as a batch item
/// ([`crate::norm::windowed`]).
pub(crate) fn burn_group_norm<B: Backend>(
    x: FloatTensor<B>,
    gamma: FloatTensor<B>,
    beta: FloatTensor<B>,
    spec: NormSpec,
) -> FloatTensor<B> {
    let y = primitive(burn_windows(
        tensor::<B, 4>(x),
        Some(tensor(gamma)),
        Some(tensor(beta)),
        spec,
    ));
    if spec.silu {
        burn_silu::<B>(y)
    } else {
        y
    }
}

/// GroupNorm over `spec`'s windows in burn's tensor operations (its SiLU
/// left to the caller): blended across their borders when `spec.blend`
/// ([`crate::norm::blended`]), else each window on its own.
fn burn_windows<B: Backend>(
    x: Tensor<B, 4>,
    gamma: Option<Tensor<B, 1>>,
    beta: Option<Tensor<B, 1>>,
    spec: NormSpec,
) -> Tensor<B, 4> {
    let parts = (spec.groups, spec.epsilon);
    if spec.blend {
        crate::norm::blended(x, gamma, beta, parts, spec.window)
    } else {
        crate::norm::windowed(x, spec.window, |x| {
            crate::norm::folded(x, gamma, beta, parts.0, parts.1)
        })
    }
}

/// GroupNorm's gradients in burn's tensor operations: with `xh` the
/// normalised input and `dxh = dy * gamma`, per (image, group) `dx = rstd *
/// (dxh - mean(dxh) - xh * mean(dxh * xh))`; `dgamma`, `dbeta` the
/// per-channel sums of `dy * xh` and `dy`.
pub(crate) fn burn_group_norm_backward<B: Backend>(
    x: FloatTensor<B>,
    gamma: FloatTensor<B>,
    dy: FloatTensor<B>,
    spec: NormSpec,
) -> [FloatTensor<B>; 3] {
    assert!(
        !spec.silu,
        "the backward of GroupNorm then SiLU is taken apart"
    );
    let (x, dy) = (tensor::<B, 4>(x), tensor::<B, 4>(dy));
    let dims = x.dims();
    let side = spec.window;
    let (x, dy) = (
        crate::norm::to_windows(x, side),
        crate::norm::to_windows(dy, side),
    );
    let [dx, dgamma, dbeta] = unwindowed_backward::<B>(x, gamma, dy, spec.groups, spec.epsilon);
    let dx = crate::norm::from_windows::<B>(tensor(dx), dims, side);
    [primitive(dx), dgamma, dbeta]
}

/// [`burn_group_norm_backward`] with statistics per (image, group).
fn unwindowed_backward<B: Backend>(
    x: Tensor<B, 4>,
    gamma: FloatTensor<B>,
    dy: Tensor<B, 4>,
    groups: usize,
    epsilon: f64,
) -> [FloatTensor<B>; 3] {
    let [n, c, h, w] = x.dims();
    let block = c / groups * h * w;
    let grouped = x.reshape([n, groups, block]);
    let centred = grouped.clone() - grouped.mean_dim(2);
    let rstd = centred
        .clone()
        .square()
        .mean_dim(2)
        .add_scalar(epsilon)
        .sqrt()
        .recip();
    let xh = (centred * rstd.clone()).reshape([n, c, h * w]);
    let dy = dy.reshape([n, c, h * w]);
    let dbeta = dy.clone().sum_dim(2).sum_dim(0).reshape([c]);
    let dgamma = (dy.clone() * xh.clone()).sum_dim(2).sum_dim(0).reshape([c]);
    let dxh = (dy * tensor::<B, 1>(gamma).reshape([1, c, 1])).reshape([n, groups, block]);
    let xh = xh.reshape([n, groups, block]);
    let m1 = dxh.clone().mean_dim(2);
    let m2 = (dxh.clone() * xh.clone()).mean_dim(2);
    let dx = ((dxh - m1 - xh * m2) * rstd).reshape([n, c, h, w]);
    [primitive(dx), primitive(dgamma), primitive(dbeta)]
}

/// burn's gradients of a convolution (what its autodiff backend computes).
pub(crate) fn burn_conv2d_backward<B: Backend>(
    x: FloatTensor<B>,
    weight: FloatTensor<B>,
    bias: Option<FloatTensor<B>>,
    dy: FloatTensor<B>,
    options: ConvOptions<2>,
    needed: Needed,
) -> ConvGrads<B> {
    ConvGrads {
        x: needed
            .x
            .then(|| B::conv2d_x_backward(x.clone(), weight.clone(), dy.clone(), options.clone())),
        weight: needed.weight.then(|| {
            B::conv2d_weight_backward(x.clone(), weight.clone(), dy.clone(), options.clone())
        }),
        bias: match bias {
            Some(b) if needed.bias => Some(B::conv2d_bias_backward(x, b, dy)),
            _ => None,
        },
    }
}

/// burn's gradients of a transposed convolution.
pub(crate) fn burn_conv_transpose2d_backward<B: Backend>(
    x: FloatTensor<B>,
    weight: FloatTensor<B>,
    bias: Option<FloatTensor<B>>,
    dy: FloatTensor<B>,
    options: ConvTransposeOptions<2>,
    needed: Needed,
) -> ConvGrads<B> {
    ConvGrads {
        x: needed
            .x
            .then(|| B::conv_transpose2d_x_backward(weight.clone(), dy.clone(), options.clone())),
        weight: needed.weight.then(|| {
            B::conv_transpose2d_weight_backward(x.clone(), weight.clone(), dy.clone(), options)
        }),
        bias: match bias {
            Some(b) if needed.bias => Some(B::conv_transpose2d_bias_backward(x, b, dy)),
            _ => None,
        },
    }
}

/// Adam's update in burn's tensor operations, in burn's order.
pub(crate) fn burn_adam<B: Backend>(
    param: FloatTensor<B>,
    grad: FloatTensor<B>,
    m: Option<FloatTensor<B>>,
    v: Option<FloatTensor<B>>,
    s: AdamStep,
) -> [FloatTensor<B>; 3] {
    let (f1, f2) = (1.0 - s.beta_1, 1.0 - s.beta_2);
    let g2 = B::float_mul_scalar(B::float_mul(grad.clone(), grad.clone()), f2.into());
    let g1 = B::float_mul_scalar(grad, f1.into());
    let (m, v) = match (m, v) {
        (Some(m), Some(v)) => (
            B::float_add(B::float_mul_scalar(m, s.beta_1.into()), g1),
            B::float_add(B::float_mul_scalar(v, s.beta_2.into()), g2),
        ),
        _ => (g1, g2),
    };
    let bc2 = (1.0 - s.beta_2.powi(s.time)).sqrt();
    let factor = bc2 / (1.0 - s.beta_1.powi(s.time));
    let denom = B::float_add_scalar(B::float_sqrt(v.clone()), (s.epsilon * bc2).into());
    let delta = B::float_div(B::float_mul_scalar(m.clone(), factor.into()), denom);
    let param = B::float_sub(param, B::float_mul_scalar(delta, s.lr.into()));
    [param, m, v]
}

impl PgrfOps for burn::backend::Flex {
    fn pgrf_kernels() -> bool {
        kernels() == Kernels::Pgrf
    }

    fn pgrf_conv2d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: Option<FloatTensor<Self>>,
        options: ConvOptions<2>,
    ) -> FloatTensor<Self> {
        flex::conv2d(x, weight, bias, options)
    }

    fn pgrf_conv2d_leaky(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: Option<FloatTensor<Self>>,
        options: ConvOptions<2>,
        slope: f32,
    ) -> FloatTensor<Self> {
        flex::conv2d_leaky(x, weight, bias, options, slope)
    }

    fn pgrf_conv2d_backward(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: Option<FloatTensor<Self>>,
        dy: FloatTensor<Self>,
        options: ConvOptions<2>,
        needed: Needed,
    ) -> ConvGrads<Self> {
        flex::conv2d_backward(x, weight, bias, dy, options, needed)
    }

    fn pgrf_conv_transpose2d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: Option<FloatTensor<Self>>,
        options: ConvTransposeOptions<2>,
    ) -> FloatTensor<Self> {
        flex::conv_transpose2d(x, weight, bias, options)
    }

    fn pgrf_conv_transpose2d_backward(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: Option<FloatTensor<Self>>,
        dy: FloatTensor<Self>,
        options: ConvTransposeOptions<2>,
        needed: Needed,
    ) -> ConvGrads<Self> {
        flex::conv_transpose2d_backward(x, weight, bias, dy, options, needed)
    }

    fn pgrf_leaky_relu(x: FloatTensor<Self>, slope: f32) -> FloatTensor<Self> {
        flex::leaky_relu(x, slope)
    }

    fn pgrf_leaky_relu_backward(
        x: FloatTensor<Self>,
        dy: FloatTensor<Self>,
        slope: f32,
    ) -> FloatTensor<Self> {
        flex::leaky_relu_backward(x, dy, slope)
    }

    fn pgrf_silu(x: FloatTensor<Self>) -> FloatTensor<Self> {
        flex::silu(x)
    }

    fn pgrf_silu_backward(x: FloatTensor<Self>, dy: FloatTensor<Self>) -> FloatTensor<Self> {
        flex::silu_backward(x, dy)
    }

    fn pgrf_group_norm(
        x: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        spec: NormSpec,
    ) -> FloatTensor<Self> {
        flex::group_norm(x, gamma, beta, spec)
    }

    fn pgrf_group_norm_backward(
        x: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        dy: FloatTensor<Self>,
        spec: NormSpec,
    ) -> [FloatTensor<Self>; 3] {
        flex::group_norm_backward(x, gamma, dy, spec)
    }

    fn pgrf_adam(
        param: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        m: Option<FloatTensor<Self>>,
        v: Option<FloatTensor<Self>>,
        step: AdamStep,
    ) -> [FloatTensor<Self>; 3] {
        flex::adam(param, grad, m, v, step)
    }
}

/// burn's CUDA backend keeps burn's operations (nothing here has been run on
/// a GPU).
#[cfg(feature = "cuda")]
impl PgrfOps for burn::backend::Cuda {}

/// A training backend whose graph and inner backend both have pgrf's
/// operations: what the training loop and the optimiser need.
pub trait PgrfAutodiff: AutodiffBackend<InnerBackend: PgrfOps> + PgrfOps {}

impl<T> PgrfAutodiff for T
where
    T: AutodiffBackend + PgrfOps,
    T::InnerBackend: PgrfOps,
{
}

fn primitive<B: Backend, const D: usize>(t: Tensor<B, D>) -> FloatTensor<B> {
    t.into_primitive().tensor()
}

fn tensor<B: Backend, const D: usize>(p: FloatTensor<B>) -> Tensor<B, D> {
    Tensor::from_primitive(TensorPrimitive::Float(p))
}

/// The symmetric zero padding (rows, columns) of `m`, `None` where it is
/// asymmetric or depends on the input size (burn pads such inputs first).
fn symmetric_padding<B: Backend>(m: &Conv2d<B>) -> Option<[usize; 2]> {
    match m.padding {
        PaddingConfig2d::Valid => Some([0, 0]),
        PaddingConfig2d::Explicit(top, left, bottom, right) => {
            (top == bottom && left == right).then_some([top, left])
        }
        // Same padding is symmetric for stride 1 and an odd kernel.
        PaddingConfig2d::Same => {
            (m.stride == [1, 1] && m.kernel_size[0] % 2 == 1 && m.kernel_size[1] % 2 == 1)
                .then(|| [(m.kernel_size[0] - 1) / 2, (m.kernel_size[1] - 1) / 2])
        }
    }
}

/// The options pgrf's convolution runs `m` with, where the backend has it
/// and `m` is within it (one group, dilation 1, symmetric padding); `None`
/// sends the caller to burn's module.
fn pgrf_conv_options<B: PgrfOps>(m: &Conv2d<B>) -> Option<ConvOptions<2>> {
    let padding = symmetric_padding(m)?;
    (B::pgrf_kernels() && m.groups == 1 && m.dilation == [1, 1])
        .then(|| ConvOptions::new(m.stride, padding, [1, 1], 1))
}

/// `m.forward(x)` through pgrf's convolution where the backend has it
/// (one group, dilation 1, symmetric padding), burn's module otherwise.
pub fn conv2d<B: PgrfOps>(m: &Conv2d<B>, x: Tensor<B, 4>) -> Tensor<B, 4> {
    match pgrf_conv_options(m) {
        Some(options) => tensor(B::pgrf_conv2d(
            primitive(x),
            primitive(m.weight.val()),
            m.bias.as_ref().map(|b| primitive(b.val())),
            options,
        )),
        None => m.forward(x),
    }
}

/// `leaky_relu(conv2d(m, x), slope)`, fused into one pass where the
/// backend has pgrf's kernels and no autodiff.
pub fn conv2d_leaky<B: PgrfOps>(m: &Conv2d<B>, x: Tensor<B, 4>, slope: f32) -> Tensor<B, 4> {
    match pgrf_conv_options(m) {
        Some(options) => tensor(B::pgrf_conv2d_leaky(
            primitive(x),
            primitive(m.weight.val()),
            m.bias.as_ref().map(|b| primitive(b.val())),
            options,
            slope,
        )),
        None => leaky_relu(m.forward(x), slope),
    }
}

/// `m.forward(x)` through pgrf's transposed convolution where the backend
/// has it, burn's module otherwise.
pub fn conv_transpose2d<B: PgrfOps>(m: &ConvTranspose2d<B>, x: Tensor<B, 4>) -> Tensor<B, 4> {
    if !B::pgrf_kernels() {
        return m.forward(x);
    }
    let options =
        ConvTransposeOptions::new(m.stride, m.padding, m.padding_out, m.dilation, m.groups);
    tensor(B::pgrf_conv_transpose2d(
        primitive(x),
        primitive(m.weight.val()),
        m.bias.as_ref().map(|b| primitive(b.val())),
        options,
    ))
}

/// LeakyReLU with `slope` below zero, one pass forward and backward where
/// the backend has pgrf's kernels.
pub fn leaky_relu<B: PgrfOps, const D: usize>(x: Tensor<B, D>, slope: f32) -> Tensor<B, D> {
    if !B::pgrf_kernels() {
        return burn::tensor::activation::leaky_relu(x, f64::from(slope));
    }
    tensor(B::pgrf_leaky_relu(primitive(x), slope))
}

/// `norm.forward(x)` (burn's GroupNorm) in one pass per (image, group)
/// forward and backward where the backend has pgrf's kernels; pgrf's folded
/// form in burn's operations ([`crate::norm::group_norm`]) otherwise.
pub fn group_norm<B: PgrfOps>(norm: &GroupNorm<B>, x: Tensor<B, 4>) -> Tensor<B, 4> {
    group_norm_windowed(norm, x, 0, false)
}

/// [`group_norm`] with its statistics taken per `window` x `window` window
/// of `x` as [`crate::norm::windowed`] cuts them (0: whole inputs), in
/// place where the backend has pgrf's kernels (no copies of the windows),
/// followed by SiLU when `then_silu`. Blended across the windows' borders
/// ([`NormSpec::blend`]) unless the pass is recorded for a backward
/// (training), on either path.
pub fn group_norm_windowed<B: PgrfOps>(
    norm: &GroupNorm<B>,
    x: Tensor<B, 4>,
    window: usize,
    then_silu: bool,
) -> Tensor<B, 4> {
    match (&norm.gamma, &norm.beta) {
        (Some(gamma), Some(beta)) if B::pgrf_kernels() => tensor(B::pgrf_group_norm(
            primitive(x),
            primitive(gamma.val()),
            primitive(beta.val()),
            NormSpec {
                groups: norm.num_groups,
                epsilon: norm.epsilon,
                window,
                blend: true,
                silu: then_silu,
            },
        )),
        _ => {
            let (gamma, beta) = (
                norm.gamma.as_ref().map(|g| g.val()),
                norm.beta.as_ref().map(|b| b.val()),
            );
            // Recorded as the kernels' autodiff records it: windows apart.
            let recorded = x.is_require_grad()
                || gamma.as_ref().is_some_and(|g| g.is_require_grad())
                || beta.as_ref().is_some_and(|b| b.is_require_grad());
            let spec = NormSpec {
                groups: norm.num_groups,
                epsilon: norm.epsilon,
                window,
                blend: !recorded,
                silu: then_silu,
            };
            let y = burn_windows(x, gamma, beta, spec);
            if then_silu {
                silu(y)
            } else {
                y
            }
        }
    }
}

/// What a GroupNorm operation needs besides its tensors: `groups` groups of
/// consecutive channels, `epsilon` inside the root (biased variance), and
/// the side of the windows its statistics are taken over (0: whole inputs;
/// [`crate::norm::windowed`]'s rule).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NormSpec {
    /// Groups of channels.
    pub groups: usize,
    /// Added to the variance inside the root.
    pub epsilon: f64,
    /// Window side in pixels (0: none).
    pub window: usize,
    /// The windows' statistics blended across their borders
    /// (`pgrf_kernels::norm::blend_weights`) instead of stepping there: forward only,
    /// what inference asks for (SR3's windows); a recorded (autodiff) pass,
    /// training, normalises each window on its own, as the built-in flows
    /// were trained.
    pub blend: bool,
    /// SiLU applied to the output (the flow network's every GroupNorm is
    /// followed by one): one pass where the backend has pgrf's kernels;
    /// the autodiff backend records the two operations apart.
    pub silu: bool,
}

/// SiLU, one pass forward and backward where the backend has pgrf's
/// kernels.
pub fn silu<B: PgrfOps, const D: usize>(x: Tensor<B, D>) -> Tensor<B, D> {
    if !B::pgrf_kernels() {
        return burn::tensor::activation::silu(x);
    }
    tensor(B::pgrf_silu(primitive(x)))
}
