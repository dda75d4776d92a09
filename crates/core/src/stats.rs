//! The one robust-statistics helper pgrf uses everywhere a typical value is
//! wanted (calibration summaries, benchmark timings).

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
