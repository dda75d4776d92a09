//! pgrf's operations on burn's Flex CPU backend: the loops of
//! `pgrf_kernels` around Flex's own matrix product (`float_matmul`, which
//! takes transposed views without copying and runs gemm on rayon's pool).
//! Anything these do not cover (other dtypes than f32, dilation, groups,
//! overlapping transposed kernels) goes to burn's operation.

use super::{
    burn_adam, burn_conv2d_backward, burn_conv_transpose2d_backward, burn_group_norm,
    burn_group_norm_backward, burn_leaky_relu_backward, burn_silu, burn_silu_backward, ConvGrads,
    Needed, NormSpec,
};
use burn::backend::Flex;
use burn::tensor::ops::{
    ActivationOps, ConvOptions, ConvTransposeOptions, FloatTensorOps, ModuleOps,
};
use burn::tensor::{DType, Shape, TensorData};
use burn_flex::FlexTensor;
use pgrf_kernels::act;
use pgrf_kernels::adam::{self, AdamStep};
use pgrf_kernels::conv::{self, ConvGeom};
use pgrf_kernels::conv_backward;
use pgrf_kernels::norm::{self, GroupShape};
use pgrf_kernels::upconv;

/// Bytes one chunk's im2col buffer may take; larger batches are processed
/// in chunks of images whose partial products are summed.
const COL_BUDGET: usize = 64 << 20;

fn is_f32(ts: &[&FlexTensor]) -> bool {
    ts.iter().all(|t| t.dtype() == DType::F32)
}

fn dims(t: &FlexTensor) -> Vec<usize> {
    let s = t.layout().shape();
    (0..s.num_dims()).map(|i| s[i]).collect()
}

/// `t` as one contiguous f32 buffer (a view when it already is one; the
/// original handle is dropped so the result may be unique).
fn contiguous(t: FlexTensor) -> FlexTensor {
    let c = t.to_contiguous();
    drop(t);
    c
}

fn values(t: &FlexTensor) -> &[f32] {
    t.as_slice::<f32>().expect("a contiguous f32 tensor")
}

fn new(data: Vec<f32>, shape: &[usize]) -> FlexTensor {
    FlexTensor::from_data(TensorData::new(data, Shape::from(shape.to_vec())))
}

fn matmul(a: FlexTensor, b: FlexTensor) -> FlexTensor {
    <Flex as FloatTensorOps<Flex>>::float_matmul(a, b)
}

/// The geometry of a convolution of an input of dims `xd` by a kernel of
/// dims `wd` (both NCHW) under `options`.
fn conv_geom(xd: &[usize], wd: &[usize], options: &ConvOptions<2>) -> ConvGeom {
    ConvGeom {
        n: xd[0],
        ci: xd[1],
        h: xd[2],
        w: xd[3],
        kh: wd[2],
        kw: wd[3],
        stride: options.stride,
        pad: options.padding,
    }
}

/// A convolution with one group and dilation 1 by pgrf's own kernel
/// ([`pgrf_kernels::conv_forward::conv2d_forward`]: im2col over row tiles
/// that stay in cache, one gemm product each, bias first); anything else
/// goes to burn's operation.
pub(super) fn conv2d(
    x: FlexTensor,
    weight: FlexTensor,
    bias: Option<FlexTensor>,
    options: ConvOptions<2>,
) -> FlexTensor {
    conv2d_then(x, weight, bias, options, None)
}

/// [`conv2d`] followed by LeakyReLU with `slope`, fused into the
/// convolution's tiles (inference); burn's convolution then pgrf's
/// activation where the convolution is not pgrf's.
pub(super) fn conv2d_leaky(
    x: FlexTensor,
    weight: FlexTensor,
    bias: Option<FlexTensor>,
    options: ConvOptions<2>,
    slope: f32,
) -> FlexTensor {
    conv2d_then(x, weight, bias, options, Some(slope))
}

fn conv2d_then(
    x: FlexTensor,
    weight: FlexTensor,
    bias: Option<FlexTensor>,
    options: ConvOptions<2>,
    leaky: Option<f32>,
) -> FlexTensor {
    let (xd, wd) = (dims(&x), dims(&weight));
    let geom = conv_geom(&xd, &wd, &options);
    let typed = is_f32(&[&x, &weight]) && bias.as_ref().is_none_or(|b| is_f32(&[b]));
    let Some((oh, ow)) = geom
        .out_hw()
        .filter(|_| typed && options.dilation == [1, 1] && options.groups == 1 && wd[1] == geom.ci)
    else {
        let y = <Flex as ModuleOps<Flex>>::conv2d(x, weight, bias, options);
        return match leaky {
            Some(slope) => leaky_relu(y, slope),
            None => y,
        };
    };
    let co = wd[0];
    let (x, weight) = (contiguous(x), contiguous(weight));
    let bias = bias.map(contiguous);
    let mut out = vec![0.0f32; geom.n * co * oh * ow];
    pgrf_kernels::conv_forward::conv2d_forward(
        values(&x),
        &geom,
        values(&weight),
        co,
        bias.as_ref().map(values),
        leaky,
        &mut out,
    );
    new(out, &[geom.n, co, oh, ow])
}

/// Gradients of a convolution with one group and dilation 1: the bias's as
/// per-channel sums of `dy`; the weight's summed over tiles of output rows
/// ([`pgrf_kernels::conv_backward::conv2d_weight_grad`]); the input's, for
/// stride 1, as the forward convolution of `dy` by the flipped kernel
/// ([`pgrf_kernels::conv_backward::conv2d_input_grad`]), otherwise per
/// chunk of images as col2im of `Wᵀ · dY`, with `dY` in the channel-major
/// layout `[co, images * pixels]`.
pub(super) fn conv2d_backward(
    x: FlexTensor,
    weight: FlexTensor,
    bias: Option<FlexTensor>,
    dy: FlexTensor,
    options: ConvOptions<2>,
    needed: Needed,
) -> ConvGrads<Flex> {
    let (xd, wd, dyd) = (dims(&x), dims(&weight), dims(&dy));
    let geom = conv_geom(&xd, &wd, &options);
    let fits = geom
        .out_hw()
        .is_some_and(|(oh, ow)| dyd == [geom.n, wd[0], oh, ow] && wd[1] == geom.ci);
    if !fits || options.dilation != [1, 1] || options.groups != 1 || !is_f32(&[&x, &weight, &dy]) {
        return burn_conv2d_backward::<Flex>(x, weight, bias, dy, options, needed);
    }
    let (n, co, k) = (geom.n, wd[0], geom.rows());
    let (oh, ow) = geom.out_hw().expect("checked");
    let per = oh * ow;
    let x = contiguous(x);
    let dy = contiguous(dy);
    let weight = contiguous(weight);
    let (xv, dyv, wv) = (values(&x), values(&dy), values(&weight));
    let bias_grad =
        (needed.bias && bias.is_some()).then(|| new(conv::channel_sums(dyv, n, co, per), &[co]));
    let weight_grad = needed.weight.then(|| {
        let mut dw = vec![0.0f32; co * k];
        conv_backward::conv2d_weight_grad(xv, &geom, dyv, co, &mut dw);
        new(dw, &wd)
    });
    let x_grad = needed.x.then(|| {
        let mut dx = pgrf_kernels::zeroed(n * geom.ci * geom.h * geom.w);
        if conv_backward::input_grad_is_a_forward(&geom) {
            conv_backward::conv2d_input_grad(dyv, &geom, wv, co, &mut dx);
        } else {
            strided_input_grad(dyv, &geom, &weight, co, &mut dx);
        }
        new(dx, &xd)
    });
    ConvGrads {
        x: x_grad,
        weight: weight_grad,
        bias: bias_grad,
    }
}

/// The input gradient of a convolution that is not a forward one (strided,
/// or padded as wide as its kernel): per chunk of images, col2im of `Wᵀ ·
/// dY` with `dY` in the channel-major layout.
fn strided_input_grad(
    dyv: &[f32],
    geom: &ConvGeom,
    weight: &FlexTensor,
    co: usize,
    dx: &mut [f32],
) {
    let (n, k) = (geom.n, geom.rows());
    let (oh, ow) = geom.out_hw().expect("a valid geometry");
    let per = oh * ow;
    let w_rows = weight.clone().reshape(Shape::from(vec![co, k]));
    let chunk = geom.images_per_chunk(COL_BUDGET);
    let plane = geom.ci * geom.h * geom.w;
    for start in (0..n).step_by(chunk) {
        let images = start..(start + chunk).min(n);
        let len = images.len() * per;
        let mut dyc = pgrf_kernels::zeroed(co * len);
        conv::to_channel_major(
            &dyv[start * co * per..images.end * co * per],
            images.len(),
            co,
            per,
            &mut dyc,
        );
        let dcol = contiguous(matmul(w_rows.clone().transpose(0, 1), new(dyc, &[co, len])));
        conv::col2im(
            values(&dcol),
            geom,
            images.len(),
            &mut dx[start * plane..images.end * plane],
        );
    }
}

/// The side `k` of a transposed convolution whose square kernel equals its
/// stride (no overlap), with no padding, one group and dilation 1: the
/// case computed as one product and a shuffle. `None` for anything else.
fn non_overlapping(weight: &FlexTensor, options: &ConvTransposeOptions<2>) -> Option<usize> {
    let wd = dims(weight);
    let k = wd[2];
    (wd[3] == k
        && options.stride == [k, k]
        && options.padding == [0, 0]
        && options.padding_out == [0, 0]
        && options.dilation == [1, 1]
        && options.groups == 1)
        .then_some(k)
}

/// Transposed convolution: for a non-overlapping kernel pgrf's
/// [`upconv::upconv_forward`] (one product per tile of input rows, shuffled
/// into the output while in cache); Flex's own operation otherwise.
pub(super) fn conv_transpose2d(
    x: FlexTensor,
    weight: FlexTensor,
    bias: Option<FlexTensor>,
    options: ConvTransposeOptions<2>,
) -> FlexTensor {
    let k = non_overlapping(&weight, &options);
    let ok = k.is_some()
        && is_f32(&[&x, &weight])
        && bias.as_ref().is_none_or(|b| b.dtype() == DType::F32)
        && dims(&x)[1] == dims(&weight)[0];
    let Some(k) = k.filter(|_| ok) else {
        return <Flex as ModuleOps<Flex>>::conv_transpose2d(x, weight, bias, options);
    };
    let g = up_geom(&dims(&x), &dims(&weight), k);
    let (x, weight) = (contiguous(x), contiguous(weight));
    let bias = bias.map(contiguous);
    let mut out = pgrf_kernels::zeroed(g.n * g.co * g.h * g.w * k * k);
    upconv::upconv_forward(
        values(&x),
        &g,
        values(&weight),
        bias.as_ref().map(values),
        &mut out,
    );
    new(out, &[g.n, g.co, g.h * k, g.w * k])
}

/// The geometry of a non-overlapping transposed convolution of an input of
/// dims `xd` by a kernel of dims `wd` (`(ci, co, k, k)`).
fn up_geom(xd: &[usize], wd: &[usize], k: usize) -> upconv::UpGeom {
    upconv::UpGeom {
        n: xd[0],
        ci: xd[1],
        co: wd[1],
        h: xd[2],
        w: xd[3],
        k,
    }
}

/// Gradients of [`conv_transpose2d`] by [`upconv::upconv_backward`] (input
/// and weight in one pass over the tiles); the bias's is the per-channel
/// sums of `dy`.
pub(super) fn conv_transpose2d_backward(
    x: FlexTensor,
    weight: FlexTensor,
    bias: Option<FlexTensor>,
    dy: FlexTensor,
    options: ConvTransposeOptions<2>,
    needed: Needed,
) -> ConvGrads<Flex> {
    let (xd, wd, dyd) = (dims(&x), dims(&weight), dims(&dy));
    let k = non_overlapping(&weight, &options).filter(|&k| {
        is_f32(&[&x, &weight, &dy]) && xd[1] == wd[0] && dyd == [xd[0], wd[1], xd[2] * k, xd[3] * k]
    });
    let Some(k) = k else {
        return burn_conv_transpose2d_backward::<Flex>(x, weight, bias, dy, options, needed);
    };
    let g = up_geom(&xd, &wd, k);
    let (x, weight, dy) = (contiguous(x), contiguous(weight), contiguous(dy));
    let dyv = values(&dy);
    let bias_grad = (needed.bias && bias.is_some()).then(|| {
        new(
            conv::channel_sums(dyv, g.n, g.co, g.h * g.w * k * k),
            &[g.co],
        )
    });
    let mut dx = needed
        .x
        .then(|| pgrf_kernels::zeroed(x.layout().num_elements()));
    let mut dw = needed
        .weight
        .then(|| pgrf_kernels::zeroed(weight.layout().num_elements()));
    upconv::upconv_backward(
        values(&x),
        &g,
        values(&weight),
        dyv,
        dx.as_deref_mut(),
        dw.as_deref_mut(),
    );
    ConvGrads {
        x: dx.map(|d| new(d, &xd)),
        weight: dw.map(|d| new(d, &wd)),
        bias: bias_grad,
    }
}

/// `f` of `x`'s values into a new tensor of its shape, or `in_place` on
/// `x`'s own buffer when nothing else holds it (inference; in training the
/// graph keeps the input for the backward).
fn map(
    x: FlexTensor,
    f: impl FnOnce(&[f32], &mut [f32]),
    in_place: impl FnOnce(&mut [f32]),
) -> FlexTensor {
    let shape = dims(&x);
    let mut x = contiguous(x);
    if let Some(buf) = x.try_storage_mut::<f32>() {
        in_place(buf);
        return x;
    }
    let mut out = pgrf_kernels::zeroed(x.layout().num_elements());
    f(values(&x), &mut out);
    new(out, &shape)
}

/// `f` of `x`'s and `dy`'s values into a new tensor of their shape.
fn map2(x: FlexTensor, dy: FlexTensor, f: impl FnOnce(&[f32], &[f32], &mut [f32])) -> FlexTensor {
    let shape = dims(&x);
    let (x, dy) = (contiguous(x), contiguous(dy));
    let mut out = pgrf_kernels::zeroed(x.layout().num_elements());
    f(values(&x), values(&dy), &mut out);
    new(out, &shape)
}

pub(super) fn leaky_relu(x: FlexTensor, slope: f32) -> FlexTensor {
    if !is_f32(&[&x]) {
        return <Flex as ActivationOps<Flex>>::leaky_relu(x, slope.into());
    }
    map(
        x,
        |x, out| act::leaky_relu(x, slope, out),
        |x| act::leaky_relu_in_place(x, slope),
    )
}

pub(super) fn leaky_relu_backward(x: FlexTensor, dy: FlexTensor, slope: f32) -> FlexTensor {
    if !is_f32(&[&x, &dy]) || dims(&x) != dims(&dy) {
        return burn_leaky_relu_backward::<Flex>(x, dy, slope);
    }
    map2(x, dy, |x, dy, out| {
        act::leaky_relu_backward(x, dy, slope, out)
    })
}

pub(super) fn silu(x: FlexTensor) -> FlexTensor {
    if !is_f32(&[&x]) {
        return burn_silu::<Flex>(x);
    }
    map(x, act::silu, act::silu_in_place)
}

pub(super) fn silu_backward(x: FlexTensor, dy: FlexTensor) -> FlexTensor {
    if !is_f32(&[&x, &dy]) || dims(&x) != dims(&dy) {
        return burn_silu_backward::<Flex>(x, dy);
    }
    map2(x, dy, act::silu_backward)
}

/// GroupNorm with its affine through `pgrf_kernels::norm`, windows in
/// place; burn's operations for other dtypes or shapes.
pub(super) fn group_norm(
    x: FlexTensor,
    gamma: FlexTensor,
    beta: FlexTensor,
    spec: NormSpec,
) -> FlexTensor {
    let Some(shape) = group_shape(&[&x, &gamma, &beta], spec) else {
        return burn_group_norm::<Flex>(x, gamma, beta, spec);
    };
    let (gamma, beta) = (contiguous(gamma), contiguous(beta));
    let xd = dims(&x);
    let x = contiguous(x);
    let mut out = pgrf_kernels::zeroed(x.layout().num_elements());
    norm::group_norm(
        values(&x),
        &shape,
        spec.epsilon,
        values(&gamma),
        values(&beta),
        &mut out,
    );
    new(out, &xd)
}

/// The GroupNorm layout of `ts[0]` (`(n, c, h, w)`, f32, with `c`-long f32
/// affine tensors after it) and its windows, `None` where the kernels do
/// not apply.
fn group_shape(ts: &[&FlexTensor], spec: NormSpec) -> Option<GroupShape> {
    let xd = dims(ts[0]);
    let groups = spec.groups;
    let ok = is_f32(ts)
        && xd.len() == 4
        && groups > 0
        && xd[1].is_multiple_of(groups)
        && ts[1..].iter().all(|t| dims(t) == [xd[1]]);
    ok.then(|| GroupShape {
        n: xd[0],
        c: xd[1],
        height: xd[2],
        width: xd[3],
        groups,
        window: crate::norm::window_of(xd[2], xd[3], spec.window),
        blend: spec.blend,
        silu: spec.silu,
    })
}

/// Gradients of [`group_norm`]: `[dx, dgamma, dbeta]`.
pub(super) fn group_norm_backward(
    x: FlexTensor,
    gamma: FlexTensor,
    dy: FlexTensor,
    spec: NormSpec,
) -> [FlexTensor; 3] {
    let shape = group_shape(&[&x, &gamma], spec)
        .filter(|s| !s.silu && dims(&dy) == dims(&x) && is_f32(&[&dy]));
    let Some(shape) = shape else {
        return burn_group_norm_backward::<Flex>(x, gamma, dy, spec);
    };
    let xd = dims(&x);
    let (x, dy, gamma) = (contiguous(x), contiguous(dy), contiguous(gamma));
    let mut dx = pgrf_kernels::zeroed(x.layout().num_elements());
    let (dgamma, dbeta) = norm::group_norm_backward(
        values(&x),
        values(&dy),
        &shape,
        spec.epsilon,
        values(&gamma),
        &mut dx,
    );
    [
        new(dx, &xd),
        new(dgamma, &[shape.c]),
        new(dbeta, &[shape.c]),
    ]
}

/// Adam in one pass, writing the parameter and the moments in place (a
/// copy first where a buffer is shared, e.g. with a checkpoint's record).
pub(super) fn adam(
    param: FlexTensor,
    grad: FlexTensor,
    m: Option<FlexTensor>,
    v: Option<FlexTensor>,
    step: AdamStep,
) -> [FlexTensor; 3] {
    let same = |t: &Option<FlexTensor>| {
        t.as_ref()
            .is_none_or(|t| t.dtype() == DType::F32 && dims(t) == dims(&param))
    };
    if !is_f32(&[&param, &grad])
        || dims(&grad) != dims(&param)
        || !same(&m)
        || !same(&v)
        || m.is_some() != v.is_some()
    {
        return burn_adam::<Flex>(param, grad, m, v, step);
    }
    let shape = dims(&param);
    let numel = param.layout().num_elements();
    let first = m.is_none();
    let mut param = contiguous(param);
    let grad = contiguous(grad);
    let mut m = m.map_or_else(|| new(pgrf_kernels::zeroed(numel), &shape), contiguous);
    let mut v = v.map_or_else(|| new(pgrf_kernels::zeroed(numel), &shape), contiguous);
    adam::adam(
        param.storage_mut::<f32>(),
        values(&grad),
        m.storage_mut::<f32>(),
        v.storage_mut::<f32>(),
        &step,
        first,
    );
    [param, m, v]
}
