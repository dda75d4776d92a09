//! Probability-plot correlation coefficient (Filliben 1975): how straight a
//! normal probability plot of a sample is. The paper uses it (Fig. 2) to show
//! that per-pixel read noise is Gaussian while the pooled, global distribution
//! of all pixels is not, which is the argument for per-pixel calibration.

/// Inverse of the standard normal CDF (Acklam's rational approximation,
/// relative error below 1.2e-9), for 0 < p < 1.
pub(crate) fn norm_ppf(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.383_577_518_672_69e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < 0.02425 {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - 0.02425 {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

/// PPCC of `sample` against the normal distribution, with Filliben's
/// plotting positions. 1 is a perfect fit; NaN for fewer than 3 values or a
/// constant sample.
pub(crate) fn ppcc(sample: &[f64]) -> f64 {
    let n = sample.len();
    if n < 3 {
        return f64::NAN;
    }
    let mut x: Vec<f64> = sample.to_vec();
    x.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    let nf = n as f64;
    let last = 0.5f64.powf(1.0 / nf);
    let m: Vec<f64> = (1..=n)
        .map(|i| {
            let p = if i == 1 {
                1.0 - last
            } else if i == n {
                last
            } else {
                (i as f64 - 0.3175) / (nf + 0.365)
            };
            norm_ppf(p)
        })
        .collect();
    let mx = x.iter().sum::<f64>() / nf;
    let mm = m.iter().sum::<f64>() / nf;
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in x.iter().zip(&m) {
        sxy += (a - mx) * (b - mm);
        sxx += (a - mx).powi(2);
        syy += (b - mm).powi(2);
    }
    if sxx == 0.0 {
        return f64::NAN;
    }
    sxy / (sxx * syy).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ppf_reference_values() {
        assert!(norm_ppf(0.5).abs() < 1e-9);
        assert!((norm_ppf(0.975) - 1.959_963_985).abs() < 1e-8);
        assert!((norm_ppf(0.01) + 2.326_347_874).abs() < 1e-8);
        assert!((norm_ppf(1e-6) + 4.753_424_309).abs() < 1e-7);
    }

    #[test]
    fn gaussian_scores_high_and_skewed_scores_low() {
        // Exact normal quantiles: PPCC ~ 1.
        let n = 64;
        let g: Vec<f64> = (1..=n)
            .map(|i| norm_ppf((i as f64 - 0.5) / n as f64))
            .collect();
        assert!(ppcc(&g) > 0.998);
        // Exponential quantiles are skewed: clearly lower.
        let e: Vec<f64> = (1..=n)
            .map(|i| -(1.0 - (i as f64 - 0.5) / n as f64).ln())
            .collect();
        assert!(ppcc(&e) < 0.95, "{}", ppcc(&e));
        assert!(ppcc(&[1.0, 1.0, 1.0]).is_nan());
    }
}
