//! What measuring a standard deviation from a few frames does to a median
//! over pixels, and how it is undone.
//!
//! A pixel's temporal noise is measured from n bias frames: its sample
//! variance is sigma^2 chi^2_nu / nu (nu = n - 1), unbiased, but its square
//! root is not, and the median over pixels of the per-pixel sample sigma
//! sits below the median of the true sigma (on pgrf's virtual sensor, whose
//! read noise spreads by 25 % over its pixels: 5.8 % with 8 frames, 2.9 %
//! with 16, 0.6 % with 64). In logs the measurement is additive:
//!
//!   ln s = ln sigma + Y,   Y = ln sqrt(chi^2_nu / nu),
//!
//! with Y's distribution known exactly, so the median of ln sigma follows
//! from the observed median of ln s once the spread of ln sigma over pixels
//! is known. That spread is taken as normal (a log-normal read noise, as
//! sensors show and the virtual sensor draws), with its width tau chosen so
//! that the model's interquartile range of ln s matches the observed one;
//! the correction is then the model's median of Y + N(0, tau^2). It is exact
//! for a sensor whose pixels all share one sigma (tau = 0) and for a spread
//! much wider than the measurement's, and a small-sample correction in
//! between. The temporal noise is taken as Gaussian (the normality check,
//! [`crate::ppcc`], says how far it is).

/// Points of the grid on which Y's density is tabulated.
const GRID: usize = 2000;

/// The distribution of Y = ln sqrt(chi^2_nu / nu), tabulated: grid points
/// and their probabilities (summing to 1).
struct LogSd {
    y: Vec<f64>,
    p: Vec<f64>,
}

impl LogSd {
    /// Y's distribution for `nu` degrees of freedom. With x = nu e^(2y) the
    /// chi^2 density x^(nu/2 - 1) e^(-x/2) dx becomes, in y, proportional
    /// to exp(nu y - nu (e^(2y) - 1) / 2) (1 at the mode y = 0); the grid
    /// spans where that is above e^-40.
    fn new(nu: f64) -> LogSd {
        let log_density = |y: f64| nu * y - 0.5 * nu * (2.0 * y).exp_m1();
        let lo = -40.0 / nu - 0.5;
        let hi = 0.5 * (1.0 + 200.0 / nu).ln();
        let step = (hi - lo) / (GRID - 1) as f64;
        let y: Vec<f64> = (0..GRID).map(|i| lo + step * i as f64).collect();
        let mut p: Vec<f64> = y.iter().map(|&v| log_density(v).exp()).collect();
        let total: f64 = p.iter().sum();
        p.iter_mut().for_each(|v| *v /= total);
        LogSd { y, p }
    }

    /// P(Y + Z <= m), Z ~ N(0, tau^2) independent of Y (tau = 0: Y alone).
    fn cdf(&self, m: f64, tau: f64) -> f64 {
        if tau <= 0.0 {
            return self
                .y
                .iter()
                .zip(&self.p)
                .filter(|(y, _)| **y <= m)
                .map(|(_, p)| p)
                .sum();
        }
        self.y
            .iter()
            .zip(&self.p)
            .map(|(&y, &p)| p * normal_cdf((m - y) / tau))
            .sum()
    }

    /// The `q` quantile of Y + N(0, tau^2), by bisection of [`LogSd::cdf`].
    fn quantile(&self, q: f64, tau: f64) -> f64 {
        let (mut lo, mut hi) = (self.y[0] - 10.0 * tau, self.y[GRID - 1] + 10.0 * tau);
        for _ in 0..50 {
            let mid = 0.5 * (lo + hi);
            if self.cdf(mid, tau) < q {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    /// Interquartile range of Y + N(0, tau^2).
    fn iqr(&self, tau: f64) -> f64 {
        self.quantile(0.75, tau) - self.quantile(0.25, tau)
    }
}

/// The standard normal CDF, from the complementary error function
/// (Abramowitz and Stegun 7.1.26, absolute error below 1.5e-7, ample for a
/// median of a density tabulated on 2000 points).
fn normal_cdf(z: f64) -> f64 {
    let x = z.abs() / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.327_591_1 * x);
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    let erfc = poly * (-x * x).exp();
    if z >= 0.0 {
        1.0 - 0.5 * erfc
    } else {
        0.5 * erfc
    }
}

/// The median over pixels of the true standard deviation, from each
/// pixel's unbiased sample variance over `frames` frames (`variances`;
/// zeros, negatives and non-finite values left out): the observed median
/// of ln s with the small-sample shift undone (module documentation).
/// `None` with fewer than two frames or no usable pixel.
pub(crate) fn median_sigma(variances: impl IntoIterator<Item = f64>, frames: usize) -> Option<f64> {
    let mut logs: Vec<f64> = variances
        .into_iter()
        .filter(|v| v.is_finite() && *v > 0.0)
        .map(|v| 0.5 * v.ln())
        .collect();
    if frames < 2 || logs.is_empty() {
        return None;
    }
    logs.sort_unstable_by(f64::total_cmp);
    let at = |q: f64| {
        let x = q * (logs.len() - 1) as f64;
        let (i, f) = (x.floor() as usize, x.fract());
        logs[i] + f * (logs[(i + 1).min(logs.len() - 1)] - logs[i])
    };
    let (median, iqr) = (at(0.5), at(0.75) - at(0.25));
    let y = LogSd::new((frames - 1) as f64);
    // The spread of ln sigma whose sum with Y has the observed IQR
    // (IQR grows with tau; a normal's IQR is 1.349 tau, so tau <= iqr / 1.349).
    let tau = if y.iqr(0.0) >= iqr {
        0.0
    } else {
        let (mut lo, mut hi) = (0.0, iqr / 1.349);
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            if y.iqr(mid) < iqr {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    };
    Some((median - y.quantile(0.5, tau)).exp())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Y's tabulated mean is E[ln chi^2_nu / nu] / 2 = (digamma(nu/2) +
    /// ln(2/nu)) / 2, by hand from the digamma function's values:
    /// digamma(3.5) = 1.103157, digamma(7.5) = 1.946757, digamma(0.5) =
    /// -1.963510; and Y's median at nu = 1 is ln sqrt(0.454936) (the chi^2_1
    /// median).
    #[test]
    fn the_log_sd_distribution_is_chi_squared() {
        for (nu, digamma) in [(7.0, 1.103157), (15.0, 1.946757), (1.0, -1.963510)] {
            let y = LogSd::new(nu);
            let mean: f64 = y.y.iter().zip(&y.p).map(|(a, p)| a * p).sum();
            let want = 0.5 * (digamma + (2.0f64 / nu).ln());
            assert!((mean - want).abs() < 1e-4, "nu {nu}: {mean} vs {want}");
        }
        let med = LogSd::new(1.0).quantile(0.5, 0.0);
        assert!((med - 0.5 * 0.454_936f64.ln()).abs() < 2e-3, "{med}");
        assert!((normal_cdf(1.0) - 0.841_344_7).abs() < 2e-7);
        assert!((normal_cdf(-2.0) - 0.022_750_1).abs() < 2e-7);
    }

    /// Pixels whose sigma spreads log-normally by 25 % (a fixed quantile
    /// grid of 4000 pixels), each measured with 8 frames (a fixed quantile
    /// grid of chi^2_7 / 7 factors): the median of the sample sigma is 4 %
    /// low, the corrected one within 0.5 % of the true median 6.3.
    #[test]
    fn the_median_is_recovered_from_eight_frames() {
        let y = LogSd::new(7.0);
        // Y's quantiles by inverse lookup of its cumulative probabilities.
        let mut cum = Vec::with_capacity(GRID);
        y.p.iter().fold(0.0, |acc, p| {
            cum.push(acc + p);
            acc + p
        });
        let y_at = |q: f64| y.y[cum.partition_point(|&c| c < q).min(GRID - 1)];
        let n = 4000;
        let variances: Vec<f64> = (0..n)
            .map(|i| {
                // Pixel i's sigma from the log-normal's quantile (i + 0.5) / n,
                // its chi^2 factor from a quantile that cycles independently.
                let u = (i as f64 + 0.5) / n as f64;
                let ln_sigma = 6.3f64.ln() + 0.25 * crate::ppcc::norm_ppf(u);
                let v = (((i * 7919) % n) as f64 + 0.5) / n as f64;
                (2.0 * (ln_sigma + y_at(v))).exp()
            })
            .collect();
        let mut plain: Vec<f64> = variances.iter().map(|v| v.sqrt()).collect();
        let plain = pgrf_core::stats::median(&mut plain);
        assert!(plain < 0.97 * 6.3, "uncorrected {plain}");
        let got = median_sigma(variances, 8).unwrap();
        assert!((got / 6.3 - 1.0).abs() < 0.005, "{got}");
        assert_eq!(median_sigma([0.0, f64::NAN], 8), None);
        assert_eq!(median_sigma([1.0], 1), None);
    }
}
