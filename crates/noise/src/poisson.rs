//! Exact Poisson sampling for any mean.
//!
//! Low-light synthesis divides a clean image by 100-300, so photon counts per
//! pixel run from 0.01 to a few thousand electrons. A Gaussian approximation
//! is wrong exactly where it matters (a handful of photons), so we sample
//! exactly: sequential-search inversion below mean 10 (expected mean + 1
//! comparisons, one uniform), and Hörmann's PTRS transformed rejection with
//! squeeze above (about 1.1 uniform pairs per sample, constant in the mean).

use pgrf_core::seed::open01;
use rand::Rng;

/// Mean at which we switch from inversion to PTRS.
pub(crate) const PTRS_THRESHOLD: f64 = 10.0;

/// One Poisson(mean) variate. Non-positive or non-finite means give 0.
#[inline]
pub(crate) fn poisson<R: Rng + ?Sized>(rng: &mut R, mean: f64) -> f64 {
    if mean.is_nan() || mean <= 0.0 || !mean.is_finite() {
        return 0.0;
    }
    if mean < PTRS_THRESHOLD {
        inversion(rng, mean)
    } else {
        ptrs(rng, mean)
    }
}

/// The search's cap: the tail beyond k = 200 has probability < 1e-150 for
/// mean < 10; the cap only guards against rounding leaving cdf a hair
/// below u.
const INVERSION_CAP: usize = 200;

/// 1 / k for k = 1..=[`INVERSION_CAP`] (entry 0 unused): the search
/// multiplies by these instead of dividing (a division's latency sat on
/// the chain of p at every step).
const RECIPROCALS: [f64; INVERSION_CAP + 1] = {
    let mut t = [0.0; INVERSION_CAP + 1];
    let mut k = 1;
    while k <= INVERSION_CAP {
        t[k] = 1.0 / k as f64;
        k += 1;
    }
    t
};

#[inline]
fn inversion<R: Rng + ?Sized>(rng: &mut R, mean: f64) -> f64 {
    let u = open01(rng);
    let mut p = (-mean).exp();
    let mut cdf = p;
    let mut k = 0;
    while u > cdf && k < INVERSION_CAP {
        k += 1;
        p *= mean * RECIPROCALS[k];
        cdf += p;
    }
    k as f64
}

/// PTRS (W. Hörmann, "The transformed rejection method for generating Poisson
/// random variables", Insurance: Mathematics and Economics 12, 1993).
///
/// Logarithms are only needed on the slow path (about 40% of draws at mean
/// 40), so they are taken there, and merged into one per iteration: profiling
/// showed `ln` at 28% of the full model's time when set up eagerly.
fn ptrs<R: Rng + ?Sized>(rng: &mut R, mean: f64) -> f64 {
    let slam = mean.sqrt();
    let b = 0.931 + 2.53 * slam;
    let a = -0.059 + 0.02483 * b;
    let vr = 0.9277 - 3.6224 / (b - 2.0);
    // (ln mean, 1/alpha): slow path only.
    let mut slow: Option<(f64, f64)> = None;
    loop {
        let u = open01(rng) - 0.5;
        let v = open01(rng);
        let us = 0.5 - u.abs();
        let k = floor((2.0 * a / us + b) * u + mean + 0.43);
        if us >= 0.07 && v <= vr {
            return k;
        }
        if k < 0.0 || (us < 0.013 && v > us) {
            continue;
        }
        let (ll, inv_alpha) = *slow.get_or_insert_with(|| (mean.ln(), 1.1239 + 1.1328 / (b - 3.4)));
        // ln v + ln(1/alpha) - ln(a/us^2 + b) as one logarithm.
        let lhs = (v * inv_alpha / (a / (us * us) + b)).ln();
        if lhs <= -mean + k * ll - ln_factorial(k) {
            return k;
        }
    }
}

/// floor() without a libm call (baseline x86-64 has no SSE4.1 round).
#[inline(always)]
fn floor(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

/// ln(k!) exactly for small k (table), by Stirling's series beyond (relative
/// error below 1e-15 for k >= 32). The table reaches k = 255 so that PTRS's
/// slow path at the means low-light scenes have (10 to ~150 electrons)
/// takes no second logarithm.
pub(crate) fn ln_factorial(k: f64) -> f64 {
    const N: usize = 256;
    static TABLE: std::sync::OnceLock<[f64; N]> = std::sync::OnceLock::new();
    let t = TABLE.get_or_init(|| {
        let mut t = [0.0; N];
        for i in 1..N {
            t[i] = t[i - 1] + (i as f64).ln();
        }
        t
    });
    if k < N as f64 {
        return t[k as usize];
    }
    let n = k + 1.0;
    let inv = 1.0 / n;
    let inv2 = inv * inv;
    (n - 0.5) * n.ln() - n
        + 0.5 * (2.0 * std::f64::consts::PI).ln()
        + inv * (1.0 / 12.0 - inv2 * (1.0 / 360.0 - inv2 * (1.0 / 1260.0 - inv2 / 1680.0)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use pgrf_core::seed::{stream, Domain};

    #[test]
    fn ln_factorial_matches_direct_sums() {
        let mut direct = 0.0;
        for k in 1..3000u32 {
            direct += (k as f64).ln();
            let got = ln_factorial(k as f64);
            assert!(
                (got - direct).abs() <= 1e-12 * direct.max(1.0),
                "k={k}: {got} vs {direct}"
            );
        }
    }

    /// Poisson pmf via logs.
    fn pmf(k: u64, mean: f64) -> f64 {
        (k as f64 * mean.ln() - mean - ln_factorial(k as f64)).exp()
    }

    /// Mean and variance within 5 standard errors, and a chi-square
    /// goodness-of-fit over bins with expected count >= 20 (tail bins pooled)
    /// below the 0.1% critical value.
    fn check(mean: f64, n: usize, seed: u64) {
        let mut rng = stream(seed, Domain::Pixel, 0, 0);
        let samples: Vec<u64> = (0..n).map(|_| poisson(&mut rng, mean) as u64).collect();
        let m = samples.iter().sum::<u64>() as f64 / n as f64;
        let var = samples.iter().map(|&x| (x as f64 - m).powi(2)).sum::<f64>() / (n - 1) as f64;
        let se_mean = (mean / n as f64).sqrt();
        assert!((m - mean).abs() < 5.0 * se_mean, "mean {mean}: got {m}");
        // Var(s^2) = mu4/n - sigma^4 (n-3)/(n(n-1)); Poisson mu4 = mean (1 + 3 mean).
        let mu4 = mean * (1.0 + 3.0 * mean);
        let se_var = ((mu4 - mean * mean * (n as f64 - 3.0) / (n as f64 - 1.0)) / n as f64).sqrt();
        assert!((var - mean).abs() < 5.0 * se_var, "mean {mean}: var {var}");

        // Chi-square over [lo, hi] with pooled tails.
        let max = *samples.iter().max().unwrap();
        let mut counts = vec![0usize; max as usize + 1];
        for &x in &samples {
            counts[x as usize] += 1;
        }
        let mut bins: Vec<(f64, f64)> = Vec::new(); // (observed, expected)
        let (mut obs_acc, mut exp_acc) = (0.0, 0.0);
        let mut cdf = 0.0;
        for k in 0..=max {
            let p = pmf(k, mean);
            cdf += p;
            obs_acc += counts[k as usize] as f64;
            exp_acc += p * n as f64;
            if exp_acc >= 20.0 && (1.0 - cdf) * n as f64 >= 20.0 {
                bins.push((obs_acc, exp_acc));
                obs_acc = 0.0;
                exp_acc = 0.0;
            }
        }
        // Remaining upper tail (including values above max).
        bins.push((obs_acc, exp_acc + (1.0 - cdf).max(0.0) * n as f64));
        let chi2: f64 = bins.iter().map(|(o, e)| (o - e).powi(2) / e).sum();
        let dof = bins.len() as f64 - 1.0;
        // Wilson-Hilferty approximation of the 99.9% quantile of chi2(dof).
        let z = 3.090_232;
        let crit = dof * (1.0 - 2.0 / (9.0 * dof) + z * (2.0 / (9.0 * dof)).sqrt()).powi(3);
        assert!(
            chi2 < crit.max(13.8),
            "mean {mean}: chi2 {chi2:.1} over {dof} dof (critical {crit:.1})"
        );
    }

    #[test]
    fn poisson_mean_variance_and_chi_square() {
        for (i, mean) in [0.01, 0.5, 5.0, 9.99, 10.0, 30.0, 1000.0]
            .into_iter()
            .enumerate()
        {
            check(mean, 200_000, 1000 + i as u64);
        }
    }

    #[test]
    fn degenerate_means_give_zero() {
        let mut rng = stream(1, Domain::Pixel, 0, 0);
        assert_eq!(poisson(&mut rng, 0.0), 0.0);
        assert_eq!(poisson(&mut rng, -3.0), 0.0);
        assert_eq!(poisson(&mut rng, f64::NAN), 0.0);
    }
}
