//! The picture of a sampling search: PSNR against the second time t of the
//! two-stage sampler, with the one-step result and the noisy input as
//! reference lines and the chosen t2 marked, so a user sees how sharp the
//! optimum is before trusting it.

use crate::chart::{
    curve, dashed, dot_key, line_key, Area, ALTERNATIVE, BASELINE, FIT, MEASURED, SEARCH,
};
use crate::png::{ensure_font, render_png, PlotResult};
use crate::ReportError;
use plotters::prelude::*;
use std::ops::Range;
use std::path::Path;

/// One search's numbers.
pub struct SearchCurve<'a> {
    /// The plot's title.
    pub title: &'a str,
    /// The second times t searched, in [0, 1], ascending.
    pub t: &'a [f64],
    /// Mean PSNR in dB of the two-stage sampler at each `t` (same length).
    pub psnr: &'a [f64],
    /// PSNR of the first stage alone (XZ), if measured.
    pub one_step: Option<f64>,
    /// PSNR of the amplified noisy input.
    pub input: Option<f64>,
    /// The chosen t2 (one of `t`), marked on the curve.
    pub best_t: f64,
}

/// Draw `c` as a PNG at `path` (written atomically); errors are one line.
pub fn write_search_plot(path: &Path, c: &SearchCurve) -> Result<(), ReportError> {
    if c.t.is_empty() || c.t.len() != c.psnr.len() {
        return Err(ReportError::Empty("search plot needs one PSNR per t"));
    }
    ensure_font()?;
    let (y0, y1) = psnr_range(c)?;
    render_png(path, (900, 600), |root| draw_search(root, c, y0..y1))
}

/// A finite PSNR, or none: a diverged run's infinite or NaN PSNR would
/// stretch the axis to nothing.
fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

/// The PSNR axis: every finite value drawn (curve and reference lines)
/// with 8 % of their spread, at least 0.2 dB, as margin on either side.
fn psnr_range(c: &SearchCurve) -> Result<(f64, f64), ReportError> {
    let all: Vec<f64> = c
        .psnr
        .iter()
        .copied()
        .chain(c.one_step)
        .chain(c.input)
        .filter_map(finite)
        .collect();
    let lo = all.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = all.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !lo.is_finite() {
        return Err(ReportError::Empty("search plot: no finite PSNR to draw"));
    }
    let pad = ((hi - lo) * 0.08).max(0.2);
    Ok((lo - pad, hi + pad))
}

/// The chart: the searched curve with its points, the chosen t2 marked,
/// the reference levels dashed across, and the legend low on the right,
/// under the curve's optimum.
fn draw_search(root: &Area, c: &SearchCurve, psnr: Range<f64>) -> PlotResult {
    let mut chart = SEARCH
        .frame(root, c.title)
        .build_cartesian_2d(0.0f64..1.0f64, psnr)?;
    SEARCH
        .mesh(
            &mut chart,
            "second time t of the two-stage sampler",
            "PSNR [dB]",
        )
        .draw()?;
    let pts: Vec<(f64, f64)> =
        c.t.iter()
            .zip(c.psnr)
            .filter(|(_, p)| p.is_finite())
            .map(|(&t, &p)| (t, p))
            .collect();
    let anno = chart.draw_series(LineSeries::new(pts.clone(), curve(MEASURED)))?;
    line_key(anno, "two-stage sampler", curve(MEASURED));
    chart.draw_series(pts.iter().map(|&p| SEARCH.point(p)))?;
    if let Some(best) = pts.iter().find(|(t, _)| (*t - c.best_t).abs() < 1e-9) {
        let anno = chart.draw_series(std::iter::once(Circle::new(*best, 8, FIT.filled())))?;
        let label = format!("t2 = {:.3} ({:.2} dB)", best.0, best.1);
        dot_key(anno, label, 6, FIT.filled());
    }
    for (v, label, colour) in [
        (c.one_step, "one step (first stage only)", ALTERNATIVE),
        (c.input, "noisy input", BASELINE),
    ] {
        if let Some(v) = v.and_then(finite) {
            let anno = chart.draw_series(dashed(vec![(0.0, v), (1.0, v)], curve(colour)))?;
            line_key(anno, format!("{label}: {v:.2} dB"), curve(colour));
        }
    }
    SEARCH.legend(&mut chart, SeriesLabelPosition::LowerRight)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plot_is_a_png_written_atomically() {
        let dir = std::env::temp_dir().join(format!("pgrf-search-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("search.png");
        let t: Vec<f64> = (1..=10).map(|i| i as f64 / 10.0).collect();
        let psnr: Vec<f64> = t
            .iter()
            .map(|t| 40.0 - 10.0 * (t - 0.4) * (t - 0.4))
            .collect();
        let curve = SearchCurve {
            title: "test",
            t: &t,
            psnr: &psnr,
            one_step: Some(38.0),
            input: Some(20.0),
            best_t: 0.4,
        };
        write_search_plot(&path, &curve).unwrap();
        let img = image::open(&path).unwrap();
        assert_eq!((img.width(), img.height()), (900, 600));
        let files: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
        assert_eq!(files.len(), 1, "no temp file left behind");
        assert!(write_search_plot(
            &path,
            &SearchCurve {
                psnr: &psnr[..3],
                ..curve
            }
        )
        .is_err());
    }
}
