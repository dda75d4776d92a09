//! Adam's update in one pass over (parameter, gradient, moments).
//!
//! burn 0.21's Adam runs ~13 full-size tensor operations per parameter
//! tensor (each allocating), 10-11 % of a training step. This is the same
//! arithmetic, in the same order per element, so a run continues from a
//! checkpoint written by burn's Adam and the other way round.

use crate::CHUNK;
use rayon::prelude::*;

/// One Adam step's constants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamStep {
    /// Learning rate.
    pub lr: f32,
    /// Decay of the first moment.
    pub beta_1: f32,
    /// Decay of the second moment.
    pub beta_2: f32,
    /// Added to the root of the second moment (scaled by its bias
    /// correction, as burn does).
    pub epsilon: f32,
    /// Step number, 1 for the first update.
    pub time: i32,
}

/// Update `param` in place with gradient `grad` and moments `m`, `v` (also
/// updated in place; ignored and overwritten when `first`):
/// `m = b1 m + (1 - b1) g`, `v = b2 v + (1 - b2) g²` (`(1 - b1) g` and
/// `(1 - b2) g²` on the first step), then `param -= lr * (m c) / (sqrt(v) +
/// eps sqrt(1 - b2^t))` with `c = sqrt(1 - b2^t) / (1 - b1^t)`.
pub fn adam(
    param: &mut [f32],
    grad: &[f32],
    m: &mut [f32],
    v: &mut [f32],
    s: &AdamStep,
    first: bool,
) {
    let n = param.len();
    assert!(
        grad.len() == n && m.len() == n && v.len() == n,
        "Adam operand sizes"
    );
    let bc2 = (1.0 - s.beta_2.powi(s.time)).sqrt();
    let factor = bc2 / (1.0 - s.beta_1.powi(s.time));
    let eps = s.epsilon * bc2;
    let (f1, f2) = (1.0 - s.beta_1, 1.0 - s.beta_2);
    param
        .par_chunks_mut(CHUNK)
        .zip(grad.par_chunks(CHUNK))
        .zip(m.par_chunks_mut(CHUNK).zip(v.par_chunks_mut(CHUNK)))
        .for_each(|((p, g), (m, v))| {
            for (((p, &g), m), v) in p.iter_mut().zip(g).zip(m).zip(v) {
                if first {
                    *m = g * f1;
                    *v = (g * g) * f2;
                } else {
                    *m = *m * s.beta_1 + g * f1;
                    *v = *v * s.beta_2 + (g * g) * f2;
                }
                *p -= (*m * factor) / (v.sqrt() + eps) * s.lr;
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three steps against the update written out in f64.
    #[test]
    fn three_steps_match_the_textbook_update() {
        let g = [[0.5f32, -1.0, 2e-3], [0.25, 0.0, -3.0], [-0.5, 1.0, 1e-4]];
        let mut p = [1.0f32, -2.0, 0.5];
        let (mut m, mut v) = ([0.0f32; 3], [0.0f32; 3]);
        let (mut pr, mut mr, mut vr) = ([1.0f64, -2.0, 0.5], [0.0f64; 3], [0.0f64; 3]);
        let (b1, b2, eps, lr) = (0.9f64, 0.999f64, 1e-8f64, 1e-3f64);
        for (t, g) in g.iter().enumerate() {
            let time = t as i32 + 1;
            let step = AdamStep {
                lr: lr as f32,
                beta_1: b1 as f32,
                beta_2: b2 as f32,
                epsilon: eps as f32,
                time,
            };
            adam(&mut p, g, &mut m, &mut v, &step, t == 0);
            for i in 0..3 {
                let gi = f64::from(g[i]);
                mr[i] = b1 * mr[i] + (1.0 - b1) * gi;
                vr[i] = b2 * vr[i] + (1.0 - b2) * gi * gi;
                let mhat = mr[i] / (1.0 - b1.powi(time));
                let vhat = vr[i] / (1.0 - b2.powi(time));
                pr[i] -= lr * mhat / (vhat.sqrt() + eps);
            }
        }
        for i in 0..3 {
            assert!(
                (f64::from(p[i]) - pr[i]).abs() < 1e-6,
                "{i}: {} vs {}",
                p[i],
                pr[i]
            );
            assert!((f64::from(m[i]) - mr[i]).abs() < 1e-6 * (1.0 + mr[i].abs()));
            assert!((f64::from(v[i]) - vr[i]).abs() < 1e-6 * (1.0 + vr[i].abs()));
        }
    }
}
