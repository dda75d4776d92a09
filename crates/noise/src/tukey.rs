//! Tukey-lambda distribution, sampled through its quantile function.
//!
//! ELD found that the read noise of several DSLRs has heavier tails than a
//! Gaussian and fits a Tukey-lambda distribution (shape lambda around -0.1..0.15).
//! Its quantile function is closed-form, Q(u) = (u^l - (1-u)^l) / l
//! (log(u / (1-u)) at l = 0), so inversion sampling is exact and cheap.

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
