//! The flow's random draws: the start X0 ~ N(0, I) of the path and the
//! training time t ~ U(0, 1) (Algorithm 1), or U(0, t_max) when training is
//! restricted to the times the two-stage sampler uses (`--time-max`). Training items draw both from
//! their own generator ([`training_start_and_time`], called by the data
//! loader); inference fills its seeded per-row start fields with the same
//! [`fill_start`] (`crate::infer::start`).

use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

/// X0 ~ N(0, I): fills `out` with independent standard normal draws, in
/// order, from `rng`.
pub(crate) fn fill_start<R: Rng + ?Sized>(rng: &mut R, out: &mut [f32]) {
    for v in out {
        *v = StandardNormal.sample(rng);
    }
}

/// t ~ U(0, t_max), the training time of one item: one uniform in [0, 1)
/// scaled by `t_max` in (0, 1] (Algorithm 1's U(0, 1) at `t_max` = 1, the
/// same bits as before the option existed: x * 1.0 is x).
///
/// Why a smaller range: the two-stage sampler evaluates the field only at
/// t = 0 and t = t2, and with the residual field the L1 velocity loss
/// weighs the image error at time t by 1 / (1 - t), so under U(0, 1) the
/// times up to t2 = 0.4 get about 15 % of the training signal (MODELS.md).
pub(crate) fn draw_time<R: Rng + ?Sized>(rng: &mut R, t_max: f32) -> f32 {
    rng.random::<f32>() * t_max
}

/// One training item's X0 (`len` values) and t ~ U(0, t_max), drawn from
/// `rng` in that order (X0 first, then t).
pub(crate) fn training_start_and_time<R: Rng + ?Sized>(
    rng: &mut R,
    len: usize,
    t_max: f32,
) -> (Vec<f32>, f32) {
    let mut x0 = vec![0.0f32; len];
    fill_start(rng, &mut x0);
    (x0, draw_time(rng, t_max))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;

    /// The draw order the data loader had before this module existed:
    /// `len` normals collected, then one uniform.
    #[test]
    fn training_draws_keep_their_order() {
        let mut a = Xoshiro256PlusPlus::seed_from_u64(3);
        let mut b = a.clone();
        let (x0, t) = training_start_and_time(&mut a, 100, 1.0);
        let x0_old: Vec<f32> = (0..100).map(|_| StandardNormal.sample(&mut b)).collect();
        let t_old = b.random::<f32>();
        assert_eq!(x0, x0_old);
        assert_eq!(t.to_bits(), t_old.to_bits());
        assert!((0.0..1.0).contains(&t));
    }

    /// t ~ U(0, t_max): 20,000 seeded draws at t_max = 0.5 stay in [0, 0.5)
    /// with mean 0.25 and variance 0.5^2 / 12 (standard errors 0.001 and
    /// 0.00013; tolerances about 4 of them), and each is the t_max = 1 draw
    /// of the same generator state halved.
    #[test]
    fn a_smaller_time_range_scales_the_uniform() {
        let mut a = Xoshiro256PlusPlus::seed_from_u64(11);
        let mut b = a.clone();
        let n = 20_000;
        let ts: Vec<f64> = (0..n)
            .map(|_| {
                let t = draw_time(&mut a, 0.5);
                assert_eq!(t.to_bits(), (draw_time(&mut b, 1.0) * 0.5).to_bits());
                assert!((0.0..0.5).contains(&t), "{t}");
                t as f64
            })
            .collect();
        let mean = ts.iter().sum::<f64>() / n as f64;
        let var = ts.iter().map(|t| (t - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        assert!((mean - 0.25).abs() < 0.004, "mean {mean}");
        assert!((var - 0.25 / 12.0).abs() < 0.0006, "variance {var}");
    }
}
