//! The robust-statistics helpers pgrf uses everywhere a typical value or
//! spread is wanted (calibration summaries and outlier tests, benchmark
//! timings).

/// The median as the sample of rank ⌊n/2⌋ after sorting: for an even count
/// that is the upper of the two middle samples (no averaging, so the result
/// is always one of the samples). NaN sorts as equal to everything it is
/// compared with; an empty slice gives NaN. Sorts `v` in place.
pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    if v.is_empty() {
        f64::NAN
    } else {
        v[v.len() / 2]
    }
}

/// The median and the robust standard deviation of `v`: 1.4826 times the
/// median absolute deviation from the median, which is the standard
/// deviation for normal data and moves little when outliers (hot pixels,
/// an odd frame) are among the values. Both by [`median`]; sorts `v`.
pub fn median_and_robust_sd(v: &mut [f64]) -> (f64, f64) {
    let med = median(v);
    let mut dev: Vec<f64> = v.iter().map(|x| (x - med).abs()).collect();
    (med, 1.4826 * median(&mut dev))
}

/// [`median`] of the finite values of `values`.
pub fn median_finite<'a>(values: impl IntoIterator<Item = &'a f32>) -> f64 {
    let mut v: Vec<f64> = values
        .into_iter()
        .filter(|x| x.is_finite())
        .map(|&x| x as f64)
        .collect();
    median(&mut v)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values 1..=9 and one outlier: median 6 (upper middle of ten), the
    /// absolute deviations 5,4,3,2,1,0,1,2,3,994 have median 3 (upper
    /// middle of 0,1,1,2,2,3,3,4,5,994).
    #[test]
    fn robust_sd_by_hand() {
        let mut v = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 1000.0];
        let (m, sd) = median_and_robust_sd(&mut v);
        assert_eq!(m, 6.0);
        assert!((sd - 1.4826 * 3.0).abs() < 1e-12, "{sd}");
    }

    #[test]
    fn odd_even_empty_and_non_finite() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        // Even count: the upper middle sample, not the mean of the two.
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 3.0);
        assert!(median(&mut []).is_nan());
        assert_eq!(
            median_finite(&[f32::NAN, 5.0, f32::INFINITY, 1.0, 3.0]),
            3.0
        );
    }
}
