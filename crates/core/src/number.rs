//! Numbers from files, shown in messages.

/// `v` as a person reads it in a one-line error: Rust's shortest form for
/// ordinary magnitudes (`1.53`, `20000`), scientific notation beyond them
/// (`1e300` rather than 301 digits, `2.5e-9`), so a damaged file's value
/// is quoted whole and the line stays short.
pub fn shown(v: f64) -> String {
    let a = v.abs();
    if v.is_finite() && a != 0.0 && !(1e-4..1e9).contains(&a) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

#[cfg(test)]
mod tests {
    use super::shown;

    #[test]
    fn ordinary_values_read_plainly_and_extreme_ones_stay_short() {
        assert_eq!(shown(1.53), "1.53");
        assert_eq!(shown(20000.0), "20000");
        assert_eq!(shown(0.0), "0");
        assert_eq!(shown(-1.5), "-1.5");
        assert_eq!(shown(1e300), "1e300");
        assert_eq!(shown(-2.5e-9), "-2.5e-9");
        assert_eq!(shown(1e9), "1e9");
        assert_eq!(shown(f64::NAN), "NaN");
        assert_eq!(shown(f64::INFINITY), "inf");
    }
}
