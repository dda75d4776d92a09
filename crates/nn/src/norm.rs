//! GroupNorm written for the layouts burn's Flex backend is fast at.
//!
//! burn's `GroupNorm` applies its affine as `x * gamma.reshape([1, c, 1, 1])`,
//! a broadcast Flex walks element by element; in SR3 that made GroupNorm 39 %
//! of the forward pass (BENCHMARKS.md, issue 5). Here the statistics are taken
//! on `(n, g, c/g * h * w)` and the affine is folded with 1/std into one scale
//! and one shift per (n, c) row of an `(n * c, h * w)` view, so every
//! full-size operation is same-shape or per-row. Same parameters, same
//! numbers (biased variance, epsilon inside the root) as `burn::nn::GroupNorm`.

use burn::nn::GroupNorm;
use burn::tensor::backend::Backend;
use burn::tensor::Tensor;

/// `norm` (burn's `GroupNorm`: its group count, epsilon and optional affine)
/// applied to `x`, `(n, c, h, w)` with `c` a multiple of the group count;
/// returns the same shape. Equal to `norm.forward(x)` to rounding, faster on
/// Flex; SR3 ([`crate::arch::sr3`]) runs every GroupNorm through it.
pub fn group_norm<B: Backend>(norm: &GroupNorm<B>, x: Tensor<B, 4>) -> Tensor<B, 4> {
    folded(
        x,
        norm.gamma.as_ref().map(|g| g.val()),
        norm.beta.as_ref().map(|b| b.val()),
        norm.num_groups,
        norm.epsilon,
    )
}

/// [`group_norm`] from its parts: `groups` groups, `epsilon`, the optional
/// per-channel scale `gamma` and shift `beta` (both or neither).
pub(crate) fn folded<B: Backend>(
    x: Tensor<B, 4>,
    gamma: Option<Tensor<B, 1>>,
    beta: Option<Tensor<B, 1>>,
    groups: usize,
    epsilon: f64,
) -> Tensor<B, 4> {
    let [n, c, h, w] = x.dims();
    let g = groups;
    let cg = c / g;
    let grouped = x.reshape([n, g, cg * h * w]);
    let mean = grouped.clone().mean_dim(2);
    let centred = grouped - mean;
    let var = centred.clone().square().mean_dim(2);
    let rstd = var.add_scalar(epsilon).sqrt().recip(); // (n, g, 1)
    let (Some(gamma), Some(beta)) = (gamma, beta) else {
        return (centred * rstd).reshape([n, c, h, w]);
    };
    let rows = centred.reshape([n * c, h * w]);
    let scale = (rstd * gamma.reshape([1, g, cg])).reshape([n * c, 1]);
    let shift = beta.reshape([1, c]).expand([n, c]).reshape([n * c, 1]);
    (rows * scale + shift).reshape([n, c, h, w])
}

/// GroupNorm (as [`folded`]) with statistics per `side` x `side` window of
/// `x` ([`window_of`]), blended across the windows' borders: a pixel near a
/// border is normalised by its window's mean and 1 / std mixed with its
/// neighbour's, so that nothing steps there (the weights of
/// `pgrf_kernels::norm::blend_weights`, as the kernel's forward; pixels away
/// from the borders keep their own window's statistics, an input of one
/// window is plain GroupNorm). Differentiable burn operations: the path of
/// backends without pgrf's kernels (CUDA).
pub(crate) fn blended<B: Backend>(
    x: Tensor<B, 4>,
    gamma: Option<Tensor<B, 1>>,
    beta: Option<Tensor<B, 1>>,
    (groups, epsilon): (usize, f64),
    side: usize,
) -> Tensor<B, 4> {
    let [n, c, h, w] = x.dims();
    let (sy, sx) = window_of(h, w, side);
    if (sy, sx) == (h, w) {
        return folded(x, gamma, beta, groups, epsilon);
    }
    let (g, cg, gy, gx) = (groups, c / groups, h / sy, w / sx);
    let windows = x
        .clone()
        .reshape([n, g, cg, gy, sy, gx, sx])
        .permute([0, 1, 3, 5, 2, 4, 6])
        .reshape([n * g, gy, gx, cg * sy * sx]);
    let mean = windows.clone().mean_dim(3);
    let var = (windows - mean.clone()).square().mean_dim(3);
    let rstd = var.add_scalar(epsilon).sqrt().recip();
    // (h, gy) and (gx, w) blending matrices: stats -> rows @ stats @ cols.
    let device = x.device();
    let matrix = |len: usize, side: usize, count: usize| {
        let mut m = vec![0.0f32; len * count];
        for (i, (j, k, t)) in pgrf_kernels::norm::blend_weights(len, side, count)
            .into_iter()
            .enumerate()
        {
            m[i * count + j] += 1.0 - t;
            m[i * count + k] += t;
        }
        Tensor::<B, 2>::from_data(burn::tensor::TensorData::new(m, [len, count]), &device)
    };
    let (rows, cols) = (matrix(h, sy, gy), matrix(w, sx, gx).transpose());
    let spread = |s: Tensor<B, 4>| {
        let s = s.reshape([n * g, gy, gx]);
        let r = rows.clone().unsqueeze::<3>().expand([n * g, h, gy]);
        let k = cols.clone().unsqueeze::<3>().expand([n * g, gx, w]);
        r.matmul(s).matmul(k).reshape([n, g, 1, h, w])
    };
    let xh = ((x.reshape([n, g, cg, h, w]) - spread(mean)) * spread(rstd)).reshape([n, c, h, w]);
    match (gamma, beta) {
        (Some(gamma), Some(beta)) => xh * gamma.reshape([1, c, 1, 1]) + beta.reshape([1, c, 1, 1]),
        _ => xh,
    }
}

/// Padding (rows, columns) that brings an `h` x `w` input to whole windows
/// of side `side`: none when the input fits in one window (it is then its
/// own window, as a training crop is), else up to the next multiple on each
/// axis. The one rule both the frame ([`crate::infer`]) and the network
/// ([`crate::arch::sr3`]) pad by, so that a padded frame's tiles need no
/// more padding inside the network.
pub fn window_padding(h: usize, w: usize, side: usize) -> (usize, usize) {
    if side == 0 || (h <= side && w <= side) {
        return (0, 0);
    }
    ((side - h % side) % side, (side - w % side) % side)
}

/// `f` applied to each `side` x `side` window of `x` `(n, c, h, w)` as if
/// it were a batch item of its own, the windows put back in place: the
/// statistics of a GroupNorm, or an attention's tokens, stay inside the
/// window. The windows sit on a grid from the input's origin; an input
/// that is one window or less, or not a whole number of windows (`side` 0:
/// none), is passed to `f` whole.
///
/// Why: a flow network's GroupNorm and attention otherwise see the whole
/// tile it is run on, so its output depends on how a frame is tiled (by
/// ~30 dB PSNR between tilings). With windows of the training crop's side
/// on the frame's grid, and tiles placed on that grid, every window's
/// statistics are those of the same pixels whatever the tiling, and the
/// same statistics the network learnt on its crops.
pub fn windowed<B: Backend>(
    x: Tensor<B, 4>,
    side: usize,
    f: impl FnOnce(Tensor<B, 4>) -> Tensor<B, 4>,
) -> Tensor<B, 4> {
    let [n, _, h, w] = x.dims();
    let y = f(to_windows(x, side));
    let co = y.dims()[1];
    from_windows(y, [n, co, h, w], side)
}

/// The (rows, columns) of the windows [`windowed`] cuts an `h` x `w` input
/// into for `side`: the whole input when `side` is 0, the input is one
/// window or less, or it is not a whole number of windows.
pub(crate) fn window_of(h: usize, w: usize, side: usize) -> (usize, usize) {
    if side == 0 || (h <= side && w <= side) || !h.is_multiple_of(side) || !w.is_multiple_of(side) {
        return (h, w);
    }
    (side, side)
}

/// `x` `(n, c, h, w)` as its windows of [`window_of`], each a batch item:
/// `(n * windows, c, side, side)` (the input itself when it is one window).
pub(crate) fn to_windows<B: Backend>(x: Tensor<B, 4>, side: usize) -> Tensor<B, 4> {
    let [n, c, h, w] = x.dims();
    let (sy, sx) = window_of(h, w, side);
    if (sy, sx) == (h, w) {
        return x;
    }
    let (gy, gx) = (h / sy, w / sx);
    x.reshape([n, c, gy, sy, gx, sx])
        .permute([0, 2, 4, 1, 3, 5])
        .reshape([n * gy * gx, c, sy, sx])
}

/// The inverse of [`to_windows`]: `y`, windows as batch items, put back in
/// place as `dims` `(n, c, h, w)` (`c` may differ from the input's).
pub(crate) fn from_windows<B: Backend>(
    y: Tensor<B, 4>,
    dims: [usize; 4],
    side: usize,
) -> Tensor<B, 4> {
    let [n, c, h, w] = dims;
    let (sy, sx) = window_of(h, w, side);
    if (sy, sx) == (h, w) {
        return y;
    }
    let (gy, gx) = (h / sy, w / sx);
    y.reshape([n, gy, gx, c, sy, sx])
        .permute([0, 3, 1, 4, 2, 5])
        .reshape([n, c, h, w])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::Cpu;
    use crate::named::{assign, collect};
    use burn::nn::GroupNormConfig;
    use burn::tensor::Distribution;

    #[test]
    fn equals_burns_group_norm() {
        let device = Default::default();
        let gn = GroupNormConfig::new(4, 16).init::<Cpu>(&device);
        let mut named = collect::<Cpu, _>(&gn);
        for t in named.values_mut() {
            for (i, v) in t.values.iter_mut().enumerate() {
                *v += 0.1 * i as f32 - 0.4;
            }
        }
        let gn = assign(gn, &named, &device).unwrap();
        let x = Tensor::<Cpu, 4>::random([3, 16, 5, 7], Distribution::Normal(0.5, 2.0), &device);
        let d: f32 = (group_norm(&gn, x.clone()) - gn.forward(x))
            .abs()
            .max()
            .into_scalar();
        assert!(d < 1e-5, "{d}");
    }

    /// Each window is normalised as a batch item of its own: equal to
    /// cutting the windows out by hand; the identity comes back in place;
    /// inputs of one window or an odd size pass whole.
    #[test]
    fn windows_are_normalised_on_their_own() {
        let device = Default::default();
        let gn = GroupNormConfig::new(2, 4).init::<Cpu>(&device);
        let x = Tensor::<Cpu, 4>::random([2, 4, 8, 12], Distribution::Normal(0.3, 1.5), &device);
        let same = windowed(x.clone(), 4, |t| t);
        assert_eq!(same.into_data(), x.clone().into_data());
        let got = windowed(x.clone(), 4, |t| group_norm(&gn, t));
        for (wy, wx) in [(0, 0), (1, 2), (0, 1)] {
            let (y0, x0) = (4 * wy, 4 * wx);
            let part = x.clone().slice([0..2, 0..4, y0..y0 + 4, x0..x0 + 4]);
            let want = group_norm(&gn, part);
            let have = got.clone().slice([0..2, 0..4, y0..y0 + 4, x0..x0 + 4]);
            let d: f32 = (want - have).abs().max().into_scalar();
            assert!(d < 1e-5, "window ({wy}, {wx}): {d}");
        }
        let whole = group_norm(&gn, x.clone());
        for side in [0, 12, 5] {
            let d: f32 = (windowed(x.clone(), side, |t| group_norm(&gn, t)) - whole.clone())
                .abs()
                .max()
                .into_scalar();
            assert!(d < 1e-6, "side {side}: {d}");
        }
        assert_eq!(window_padding(100, 60, 128), (0, 0));
        assert_eq!(window_padding(130, 60, 128), (126, 68));
        assert_eq!(window_padding(256, 384, 128), (0, 0));
        assert_eq!(window_padding(256, 384, 0), (0, 0));
    }
}
