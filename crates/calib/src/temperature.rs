//! How the dark current grows with the sensor's temperature: from dark
//! frames at two or more temperatures, the rate at each (the median over
//! pixels of the longest exposure's mean minus the master bias, over the
//! dark law's g(t)) and the temperature rise that doubles it,
//! ln 2 / slope of ln rate against temperature (least squares), as
//! astrophotography tools scale a dark library to a light's temperature.

use crate::error::{CalibError, Result};
use crate::estimate::BiasEstimate;
use crate::stack::{read_stack, ReadOptions, Stack};
use pgrf_core::stats::median;
use pgrf_noise::DarkLaw;
use std::path::PathBuf;

/// How far (degrees C) from the calibration's temperature a light's dark
/// current is scaled by the doubling temperature; beyond, the law is
/// extrapolated too far to trust and the light is refused.
pub const DARK_SCALE_RANGE_C: f32 = 10.0;

/// The dark rate of `stack` at its temperature, DN per unit of the law's
/// g(t): its longest exposure's per-pixel mean minus the bias's, median over
/// pixels, over g(t). None without a positive exposure or signal.
pub(crate) fn median_rate(stack: &Stack, bias: &BiasEstimate, law: DarkLaw) -> Option<f64> {
    let g = stack
        .groups
        .iter()
        .max_by(|a, b| a.exposure_s.total_cmp(&b.exposure_s))?;
    let gt = law.electrons(1.0, g.exposure_s);
    let mean = g.stats.mean();
    let mut signal: Vec<f64> = mean
        .iter()
        .zip(bias.mean.iter())
        .map(|(d, b)| d - b)
        .collect();
    let rate = median(&mut signal) / gt;
    (gt > 0.0 && rate.is_finite() && rate > 0.0).then_some(rate)
}

/// The dark frames `files` taken at other temperatures than the
/// calibration's, grouped by their recorded temperature (to 0.5 degrees C),
/// each group's rate ([`median_rate`]) with its median temperature.
pub(crate) fn rates_by_temperature(
    files: &[PathBuf],
    opt: &ReadOptions,
    bias: &BiasEstimate,
    law: DarkLaw,
) -> Result<Vec<(f32, f64)>> {
    let mut groups: Vec<(i32, Vec<PathBuf>, Vec<f64>)> = Vec::new();
    for f in files {
        // The temperatures from the files' metadata; each group's frames are
        // then decoded once, by its own stack.
        let Some(t) = pgrf_raw::read_temperature(f)? else {
            return Err(CalibError::BadOption {
                flag: "--temperature-darks",
                message: format!(
                    "{} records no sensor temperature (EXIF AmbientTemperature, FITS CCD-TEMP)",
                    f.display()
                ),
            });
        };
        let key = (t * 2.0).round() as i32;
        match groups.iter_mut().find(|g| g.0 == key) {
            Some(g) => {
                g.1.push(f.clone());
                g.2.push(t as f64);
            }
            None => groups.push((key, vec![f.clone()], vec![t as f64])),
        }
    }
    let mut out = Vec::new();
    for (_, files, mut temps) in groups {
        let stack = read_stack(&files, opt)?;
        if let Some(r) = median_rate(&stack, bias, law) {
            out.push((median(&mut temps) as f32, r));
        }
    }
    Ok(out)
}

/// The doubling temperature of `points` (temperature, rate): ln 2 over the
/// least-squares slope of ln rate against temperature. None with fewer
/// than two temperatures 1 degree C apart, or a rate that does not grow.
pub fn doubling_temperature(points: &[(f32, f64)]) -> Option<f64> {
    let n = points.len() as f64;
    let (lo, hi) = points
        .iter()
        .fold((f32::MAX, f32::MIN), |(l, h), p| (l.min(p.0), h.max(p.0)));
    if points.len() < 2 || hi - lo < 1.0 {
        return None;
    }
    let mt = points.iter().map(|p| p.0 as f64).sum::<f64>() / n;
    let ml = points.iter().map(|p| p.1.ln()).sum::<f64>() / n;
    let (sxy, sxx) = points.iter().fold((0.0, 0.0), |(xy, xx), p| {
        let dt = p.0 as f64 - mt;
        (xy + dt * (p.1.ln() - ml), xx + dt * dt)
    });
    let slope = sxy / sxx;
    (slope > 0.0 && slope.is_finite()).then(|| std::f64::consts::LN_2 / slope)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rates doubling every 6 degrees, exactly and with 2 % scatter.
    #[test]
    fn the_doubling_temperature_of_exact_and_noisy_rates() {
        let at = |t: f32| 10.0 * 2f64.powf(t as f64 / 6.0);
        let exact = [(-10.0, at(-10.0)), (-4.0, at(-4.0)), (2.0, at(2.0))];
        assert!((doubling_temperature(&exact).unwrap() - 6.0).abs() < 1e-9);
        let noisy = [
            (-10.0, at(-10.0) * 1.02),
            (-4.0, at(-4.0) * 0.98),
            (2.0, at(2.0)),
        ];
        assert!((doubling_temperature(&noisy).unwrap() - 6.0).abs() < 0.3);
        assert_eq!(doubling_temperature(&exact[..1]), None);
        assert_eq!(doubling_temperature(&[(0.0, 5.0), (0.4, 6.0)]), None);
        assert_eq!(doubling_temperature(&[(0.0, 5.0), (5.0, 4.0)]), None);
    }
}
