//! The flow's random draws: the start X0 ~ N(0, I) of the path and the
//! training time t ~ U(0, 1) (Algorithm 1). Training items draw both from
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

/// t ~ U(0, 1), the training time of one item.
pub(crate) fn draw_time<R: Rng + ?Sized>(rng: &mut R) -> f32 {
    rng.random::<f32>()
}

/// One training item's X0 (`len` values) and t, drawn from `rng` in that
/// order (X0 first, then t).
pub(crate) fn training_start_and_time<R: Rng + ?Sized>(rng: &mut R, len: usize) -> (Vec<f32>, f32) {
    let mut x0 = vec![0.0f32; len];
    fill_start(rng, &mut x0);
    (x0, draw_time(rng))
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
        let (x0, t) = training_start_and_time(&mut a, 100);
        let x0_old: Vec<f32> = (0..100).map(|_| StandardNormal.sample(&mut b)).collect();
        let t_old = b.random::<f32>();
        assert_eq!(x0, x0_old);
        assert_eq!(t.to_bits(), t_old.to_bits());
        assert!((0.0..1.0).contains(&t));
    }
}
