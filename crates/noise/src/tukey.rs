//! Tukey-lambda distribution, sampled through its quantile function.
//!
//! ELD found that the read noise of several DSLRs has heavier tails than a
//! Gaussian and fits a Tukey-lambda distribution (shape lambda around -0.1..0.15).
//! Its quantile function is closed-form, Q(u) = (u^l - (1-u)^l) / l
//! (log(u / (1-u)) at l = 0), so inversion sampling is exact and cheap.

use crate::fast;

/// Quantile function Q(u; lambda), u in (0, 1).
#[inline]
pub(crate) fn quantile(u: f64, lambda: f64) -> f64 {
    let (a, b) = (u.ln(), (1.0 - u).ln());
    if lambda.abs() < 1e-12 {
        a - b
    } else {
        // (e^{l a} - e^{l b}) / l, written with expm1 to stay accurate as l -> 0.
        ((lambda * a).exp_m1() - (lambda * b).exp_m1()) / lambda
    }
}

/// Shapes for which [`quantiles_in_place`] runs its vector loop: away from
/// 0, where (e^{l a} - e^{l b}) / l loses the digits `expm1` keeps, and
/// below where e^{l ln u} leaves the range of [`fast::exp`] (|l ln u| <= l
/// 37.5 for the uniforms of `open01`).
const VECTOR_LAMBDA: std::ops::RangeInclusive<f64> = 1e-6..=10.0;

/// Q(u; lambda) of every u in `us`, in place: what [`quantile`] gives each
/// (within 1e-9 of 1 + |Q|; the caller keeps an f32), in a branch-free loop the compiler vectorises
/// for the CPU it runs on. Why: two logarithms and two `expm1` calls of
/// libm per read-noise sample were 16 ns of the ELD model's ~75 ns a pixel
/// (BENCHMARKS.md, "The Python package against ELD's numpy noise model").
pub(crate) fn quantiles_in_place(us: &mut [f64], lambda: f64) {
    if VECTOR_LAMBDA.contains(&lambda.abs()) {
        vector_quantiles(us, lambda);
    } else {
        for u in us.iter_mut() {
            *u = quantile(*u, lambda);
        }
    }
}

#[multiversion::multiversion(targets = "simd")]
fn vector_quantiles(us: &mut [f64], lambda: f64) {
    let inv = 1.0 / lambda;
    for u in us.iter_mut() {
        let (a, b) = (fast::ln(*u), fast::ln(1.0 - *u));
        *u = (fast::exp(lambda * a) - fast::exp(lambda * b)) * inv;
    }
}

/// dQ/du: the reciprocal of the density at Q(u), used for standard errors.
#[cfg(test)]
fn quantile_slope(u: f64, lambda: f64) -> f64 {
    u.powf(lambda - 1.0) + (1.0 - u).powf(lambda - 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use pgrf_core::seed::{open01, stream, Domain};

    #[test]
    fn closed_form_reference_points() {
        // lambda = 0 is the logistic distribution.
        assert!((quantile(0.75, 0.0) - 3f64.ln()).abs() < 1e-12);
        // lambda = 1 is uniform on (-1, 1): Q(u) = 2u - 1.
        assert!((quantile(0.3, 1.0) - (-0.4)).abs() < 1e-12);
        // lambda = 0.14 approximates a normal with sd 1/0.5 ... here just symmetry.
        assert!((quantile(0.2, 0.14) + quantile(0.8, 0.14)).abs() < 1e-12);
        // Continuity at lambda -> 0.
        assert!((quantile(0.9, 1e-9) - quantile(0.9, 0.0)).abs() < 1e-8);
    }

    /// The vector loop gives what the scalar quantile gives, to 1e-9 of
    /// 1 + |Q| (the value is used as an f32, whose step is 6e-8), over the whole range of `open01` (its extremes 2^-54 and
    /// 1 - 2^-53, the centre, seeded uniforms) and shapes on both sides of
    /// the vector range's limits.
    #[test]
    fn the_vector_loop_matches_the_scalar_quantile() {
        let mut rng = stream(7, Domain::Pixel, 0, 0);
        let mut us: Vec<f64> = (0..20_000).map(|_| open01(&mut rng)).collect();
        let tiny = 0.5f64.powi(54);
        us.extend([
            tiny,
            0.5f64.powi(53),
            1.0 - 0.5f64.powi(53),
            0.5,
            0.5 + 1e-12,
            1e-300f64.max(tiny),
        ]);
        for lambda in [-0.2, -0.0441, -2e-6, 5e-7, 0.0, 1e-3, 0.14, 1.0, 9.0, 12.0] {
            let mut got = us.clone();
            quantiles_in_place(&mut got, lambda);
            for (&u, &q) in us.iter().zip(&got) {
                let want = quantile(u, lambda);
                assert!(
                    (q - want).abs() <= 1e-9 * (1.0 + want.abs()),
                    "lambda {lambda} u {u:e}: {q} vs {want}"
                );
            }
        }
        for &u in &us {
            assert!(
                (fast::ln(u) - u.ln()).abs() <= 1e-15 * (1.0 + u.ln().abs()),
                "ln {u:e}"
            );
        }
    }

    #[test]
    fn sample_quantiles_match_the_closed_form() {
        let n = 200_000;
        for (i, lambda) in [-0.14, -0.05, 0.0, 0.14].into_iter().enumerate() {
            let mut rng = stream(50 + i as u64, Domain::Pixel, 0, 0);
            let mut xs: Vec<f64> = (0..n).map(|_| quantile(open01(&mut rng), lambda)).collect();
            xs.sort_by(|a, b| a.partial_cmp(b).unwrap());
            for p in [0.01, 0.05, 0.25, 0.5, 0.75, 0.95, 0.99] {
                let emp = xs[(p * n as f64) as usize];
                // SE of a sample quantile: sqrt(p(1-p)/n) / f(Q(p)) = sqrt(p(1-p)/n) Q'(p).
                let se = (p * (1.0 - p) / n as f64).sqrt() * quantile_slope(p, lambda);
                let want = quantile(p, lambda);
                assert!(
                    (emp - want).abs() < 5.0 * se,
                    "lambda {lambda} p {p}: {emp} vs {want} (se {se})"
                );
            }
        }
    }
}
