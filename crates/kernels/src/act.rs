//! Activations forward and backward in one pass each.
//!
//! burn 0.21 builds LeakyReLU from a mask, a scaled copy and a select, and
//! SiLU from a sigmoid (one scalar `expf` per element) and a product, each
//! with its own node in the autodiff graph; the backward passes repeat that.
//! Here every function reads its inputs once and writes its output once,
//! and SiLU's exp is a branch-free polynomial ([`exp`]) that the compiler
//! vectorises.

use crate::CHUNK;
use rayon::prelude::*;

/// `e^x` for f32, branch-free so loops over it vectorise: `x = n ln 2 + r`
/// with `|r| <= ln 2 / 2`, a degree-6 Taylor polynomial for `e^r` (relative
/// error below 2e-7 there) and `2^n` built in the exponent bits. Inputs are
/// clamped to [-87, 88] (results between 1.6e-38 and 1.7e38, so no
/// denormals and no overflow); NaN stays NaN.
#[inline(always)]
pub fn exp(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    // ln 2 split in two so that n * LN2_HI is exact for |n| < 2^9.
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    // 1.5 * 2^23: adding it rounds to an integer held in the low mantissa bits.
    const ROUND: f32 = 12_582_912.0;
    let c = x.clamp(-87.0, 88.0);
    let t = c * LOG2E + ROUND;
    let n = t - ROUND;
    let bits = (t.to_bits() as i32).wrapping_sub(ROUND.to_bits() as i32);
    let r = (c - n * LN2_HI) - n * LN2_LO;
    let p = 1.0
        + r * (1.0
            + r * (0.5
                + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0))))));
    let scale = f32::from_bits(((bits + 127) << 23) as u32);
    let y = p * scale;
    if x.is_nan() {
        x
    } else {
        y
    }
}

/// The logistic function `1 / (1 + e^-x)` through [`exp`].
#[inline(always)]
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + exp(-x))
}

/// SiLU of one value, `x * sigmoid(x)`: the element-wise [`silu`] and the
/// GroupNorm's fused SiLU (`crate::norm`).
#[inline(always)]
pub fn silu_of(x: f32) -> f32 {
    x * sigmoid(x)
}

/// Apply `f` to every element of `x`, writing `out`, in parallel chunks.
fn map1(x: &[f32], out: &mut [f32], f: impl Fn(f32) -> f32 + Sync) {
    assert_eq!(x.len(), out.len(), "input and output sizes");
    out.par_chunks_mut(CHUNK)
        .zip(x.par_chunks(CHUNK))
        .for_each(|(o, i)| {
            for (o, &v) in o.iter_mut().zip(i) {
                *o = f(v);
            }
        });
}

/// Apply `f` to every element of `x` in place, in parallel chunks.
fn map_in_place(x: &mut [f32], f: impl Fn(f32) -> f32 + Sync) {
    x.par_chunks_mut(CHUNK).for_each(|c| {
        for v in c {
            *v = f(*v);
        }
    });
}

/// Apply `f(x, dy)` element by element, writing `out`, in parallel chunks.
fn map2(x: &[f32], dy: &[f32], out: &mut [f32], f: impl Fn(f32, f32) -> f32 + Sync) {
    assert_eq!(x.len(), out.len(), "input and output sizes");
    assert_eq!(dy.len(), out.len(), "gradient and output sizes");
    out.par_chunks_mut(CHUNK)
        .zip(x.par_chunks(CHUNK).zip(dy.par_chunks(CHUNK)))
        .for_each(|(o, (i, g))| {
            for ((o, &v), &d) in o.iter_mut().zip(i).zip(g) {
                *o = f(v, d);
            }
        });
}

/// LeakyReLU: `x` for `x >= 0`, `slope * x` below (burn's convention).
pub fn leaky_relu(x: &[f32], slope: f32, out: &mut [f32]) {
    map1(x, out, |v| if v < 0.0 { v * slope } else { v });
}

/// [`leaky_relu`] overwriting its input (inference, where nothing else
/// holds the input).
pub fn leaky_relu_in_place(x: &mut [f32], slope: f32) {
    map_in_place(x, |v| if v < 0.0 { v * slope } else { v });
}

/// LeakyReLU's input gradient from its input `x` and output gradient `dy`:
/// `dy` where `x >= 0`, `slope * dy` below (burn's derivative at 0 is 1).
pub fn leaky_relu_backward(x: &[f32], dy: &[f32], slope: f32, out: &mut [f32]) {
    map2(x, dy, out, |v, d| if v < 0.0 { d * slope } else { d });
}

/// SiLU, `x * sigmoid(x)`.
pub fn silu(x: &[f32], out: &mut [f32]) {
    map1(x, out, silu_of);
}

/// [`silu`] overwriting its input.
pub fn silu_in_place(x: &mut [f32]) {
    map_in_place(x, silu_of);
}

/// SiLU's input gradient: `dy * s * (1 + x * (1 - s))` with `s =
/// sigmoid(x)`.
pub fn silu_backward(x: &[f32], dy: &[f32], out: &mut [f32]) {
    map2(x, dy, out, |v, d| {
        let s = sigmoid(v);
        d * s * (1.0 + v * (1.0 - s))
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_is_within_a_few_ulp_of_libm() {
        let mut worst = 0.0f64;
        let steps = 200_000;
        for i in 0..=steps {
            let x = -87.0 + 175.0 * i as f32 / steps as f32;
            let want = f64::from(x).exp();
            let rel = ((f64::from(exp(x)) - want) / want).abs();
            worst = worst.max(rel);
        }
        assert!(worst < 4e-7, "worst relative error {worst:e}");
        assert_eq!(exp(0.0), 1.0);
        assert!(exp(f32::NAN).is_nan());
        assert!(exp(1000.0).is_finite() && exp(1000.0) > 1e38);
        assert!(exp(-1000.0) >= 0.0 && exp(-1000.0) < 2e-38);
    }

    #[test]
    fn silu_and_its_gradient_match_the_definitions() {
        let x: Vec<f32> = (0..1000).map(|i| (i as f32 - 500.0) / 25.0).collect();
        let dy: Vec<f32> = (0..1000).map(|i| 1.0 + (i % 7) as f32 / 7.0).collect();
        let (mut y, mut dx) = (vec![0.0; 1000], vec![0.0; 1000]);
        silu(&x, &mut y);
        silu_backward(&x, &dy, &mut dx);
        let mut inplace = x.clone();
        silu_in_place(&mut inplace);
        assert_eq!(inplace, y);
        for i in 0..1000 {
            let v = f64::from(x[i]);
            let s = 1.0 / (1.0 + (-v).exp());
            assert!(
                (f64::from(y[i]) - v * s).abs() < 1e-6 * (1.0 + v.abs()),
                "{v}"
            );
            let g = f64::from(dy[i]) * s * (1.0 + v * (1.0 - s));
            assert!((f64::from(dx[i]) - g).abs() < 1e-6 * (1.0 + g.abs()), "{v}");
        }
        let mut big = [0.0f32; 2];
        silu(&[100.0, -100.0], &mut big);
        assert_eq!(big[0], 100.0);
        assert!(big[1] <= 0.0 && big[1] > -1e-30);
    }

    #[test]
    fn leaky_relu_follows_burns_convention() {
        let x = [-2.0, -0.0, 0.0, 3.0];
        let (mut y, mut dx) = ([0.0f32; 4], [0.0f32; 4]);
        leaky_relu(&x, 0.2, &mut y);
        leaky_relu_backward(&x, &[1.0; 4], 0.2, &mut dx);
        assert_eq!(y, [-0.4, -0.0, 0.0, 3.0]);
        let mut inplace = x;
        leaky_relu_in_place(&mut inplace, 0.2);
        assert_eq!(inplace, y);
        assert_eq!(dx, [0.2, 1.0, 1.0, 1.0]);
    }
}
