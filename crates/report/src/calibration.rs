//! Human-readable calibration report: a handful of PNG plots and a Markdown
//! summary written next to the calibration file.
//!
//! The numbers in a calibration file are only as good as the frames behind
//! them, and the usual failures (a light leak in the bias frames, a flat level
//! that clipped, a sensor whose dark current follows neither law) are obvious
//! in a plot and invisible in a table. The report exists so a person can check
//! a calibration in a few seconds before trusting it.
//!
//! Everything here must work headless and without system fonts (calibration
//! runs on build machines and in containers), which is why the font is the
//! embedded DejaVu Sans and the bitmaps are encoded by the `image` crate rather
//! than by plotters.

use crate::chart::{
    bars, curve, dashed, line_key, marker, note_style, quiet_note_style, swatch_key,
    swatch_line_key, thin_curve, Area, BARS, FIRST_OF_TWO, FIT, REFERENCE, REPORT, SECOND_OF_TWO,
};
use crate::error::ReportError;
use crate::png::{encode_png, ensure_font, render_png, PlotResult};
use ndarray::{s, ArrayView3};
use plotters::coord::combinators::WithKeyPoints;
use plotters::coord::ranged1d::{Ranged, ValueFormatter};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// One flat-field level of the photon-transfer curve: bias-corrected mean signal
/// and temporal variance (from frame pairs), both in DN / DN^2.
#[derive(Clone, Copy, Debug)]
pub struct PtcPoint {
    /// Mean signal above the bias, DN (x axis).
    pub mean_dn: f64,
    /// Temporal (shot-noise) variance above the bias's, DN^2 (y axis).
    pub var_dn2: f64,
}

/// Everything the report shows, borrowed from the calibration run so that
/// writing a report never copies the full-resolution maps.
pub struct ReportData<'a> {
    /// e.g. "Sony ILCE-7SM2"
    pub camera: String,
    /// ISO of the calibration frames, for titles (None: unknown).
    pub iso: Option<u32>,
    /// Photon-transfer points, one per flat level (may be empty).
    pub ptc_points: Vec<PtcPoint>,
    /// Fitted line var = slope * mean + intercept (slope is the system gain K in DN/e-), if any.
    pub ptc_fit: Option<(f64, f64)>,
    /// Per-pixel temporal read-noise sigma in DN, packed planes (4, H, W) in order R, G1, B, G2.
    pub sigma_read: ArrayView3<'a, f32>,
    /// Per-pixel fixed-pattern offset (bias mean minus black level) in DN, shape (4, H, W).
    pub fixed_pattern: ArrayView3<'a, f32>,
    /// Per-pixel R^2 of the dark-current fit y = a*sqrt(t) (None when no dark frames).
    pub r2_sqrt: Option<ArrayView3<'a, f32>>,
    /// Per-pixel R^2 of the dark-current fit y = a*t (None when no dark frames).
    pub r2_linear: Option<ArrayView3<'a, f32>>,
    /// Whether both fits carry the offset term c (y = a g(t) + c).
    pub dark_offset: bool,
    /// The median read noise the summary table states, DN: the true
    /// per-pixel sigma's, corrected for the frames' sampling error, which
    /// the histogram marks (None: the map's own median).
    pub read_sigma_median: Option<f64>,
    /// The frames' sensor temperature, degrees C, for titles where no ISO
    /// is recorded (a CCD's frames).
    pub temperature_c: Option<f32>,
    /// Temporal noise variance without light (read, row and offset drift),
    /// DN^2: with the flat levels' shot variance it gives their SNR.
    pub dark_var_dn2: f64,
    /// A monochrome sensor: maps are drawn as one image (the packed planes
    /// are its 2x2 sub-lattices), not as four CFA planes.
    pub mono: bool,
    /// Rows of the summary table: (quantity, value, unit), EMVA 1288 vocabulary
    /// (system gain, temporal dark noise, DSNU, PRNU, dark current ...), already formatted.
    pub summary: Vec<(String, String, String)>,
}

/// File names are fixed so scripts and the Markdown links can rely on them.
const PTC_PNG: &str = "ptc.png";
const SIGMA_HIST_PNG: &str = "sigma_hist.png";
const DARK_R2_HIST_PNG: &str = "dark_r2_hist.png";
const FIXED_PATTERN_PNG: &str = "fixed_pattern.png";
const SIGMA_MAP_PNG: &str = "sigma_map.png";
const SNR_PNG: &str = "snr.png";
const SUMMARY_MD: &str = "summary.md";

/// Every file [`write_report`] may write into its folder, so a caller can
/// check them all before hours of work (none may be a folder or an input).
pub const REPORT_FILES: [&str; 7] = [
    PTC_PNG,
    SNR_PNG,
    SIGMA_HIST_PNG,
    DARK_R2_HIST_PNG,
    FIXED_PATTERN_PNG,
    SIGMA_MAP_PNG,
    SUMMARY_MD,
];

/// Plot size: tick labels stay legible when a Markdown preview scales the
/// plot down to page width, and the PNGs stay well under a megabyte.
const PLOT_W: u32 = 1100;
const PLOT_H: u32 = 700;

/// Maps larger than this on a side are strided down: the point of the map is
/// to spot structure (banding, amp glow, clusters), which survives striding,
/// and a full-resolution mosaic of a 24 MP sensor is tens of MB of noisy PNG.
const MAP_MAX_SIDE: usize = 1600;

/// Write the report into `dir`: ptc.png, sigma_hist.png, dark_r2_hist.png
/// (only with dark-current fits), fixed_pattern.png, sigma_map.png and
/// summary.md, which links them. Returns the paths written.
///
/// `dir` must already exist: it is chosen by the caller (usually next to the
/// calibration file), and silently creating a mistyped folder would hide the
/// report. Each file is written atomically and summary.md last, so an
/// interrupted run never leaves a summary pointing at half-written plots.
/// Missing or empty inputs skip their plot instead of failing, because a
/// partial calibration (bias frames only, no flats or darks) is a normal run;
/// summary.md says what was skipped and why.
pub fn write_report(dir: &Path, data: &ReportData) -> Result<Vec<PathBuf>, ReportError> {
    if !dir.exists() {
        return Err(ReportError::MissingDir(dir.to_path_buf()));
    }
    if !dir.is_dir() {
        return Err(ReportError::NotADir(dir.to_path_buf()));
    }
    check_planes("sigma_read", &data.sigma_read)?;
    check_planes("fixed_pattern", &data.fixed_pattern)?;
    if let Some(r2) = &data.r2_sqrt {
        check_planes("r2_sqrt", r2)?;
    }
    if let Some(r2) = &data.r2_linear {
        check_planes("r2_linear", r2)?;
    }
    ensure_font()?;

    let title = report_title(data);
    let sections = [
        ptc_section(dir, data, &title)?,
        snr_section(dir, data, &title)?,
        sigma_hist_section(dir, data, &title)?,
        dark_r2_section(dir, data, &title)?,
        map_section(
            dir,
            FIXED_PATTERN_PNG,
            "Fixed-pattern offset map",
            "bias mean minus black level",
            "DN",
            &data.fixed_pattern,
            data.mono,
        )?,
        map_section(
            dir,
            SIGMA_MAP_PNG,
            "Read-noise map",
            "per-pixel temporal read noise",
            "DN",
            &data.sigma_read,
            data.mono,
        )?,
    ];
    let mut written: Vec<PathBuf> = sections.iter().filter_map(|s| s.path.clone()).collect();

    let md = summary_markdown(&title, data, &sections);
    let md_path = dir.join(SUMMARY_MD);
    pgrf_core::write_atomic(&md_path, md.as_bytes())?;
    written.push(md_path);
    Ok(written)
}

/// One entry of the "Plots" part of summary.md: either the file that was
/// written with a caption saying how to read it, or the reason it was not.
struct Section {
    heading: &'static str,
    file: &'static str,
    path: Option<PathBuf>,
    /// Caption when written, reason when skipped.
    text: String,
}

impl Section {
    fn written(heading: &'static str, file: &'static str, path: PathBuf, text: String) -> Self {
        Section {
            heading,
            file,
            path: Some(path),
            text,
        }
    }

    fn skipped(heading: &'static str, file: &'static str, reason: String) -> Self {
        Section {
            heading,
            file,
            path: None,
            text: reason,
        }
    }
}

/// The plane layout is the contract with the rest of the crate; a wrong
/// plane count means the caller packed the maps differently and every
/// label in the report would lie.
fn check_planes(name: &str, a: &ArrayView3<f32>) -> Result<(), ReportError> {
    if a.shape()[0] != 4 {
        return Err(ReportError::Invalid(format!(
            "{name} has {} planes, expected 4 (R, G1, B, G2)",
            a.shape()[0]
        )));
    }
    Ok(())
}

fn report_title(data: &ReportData) -> String {
    let camera = data.camera.trim();
    let camera = if camera.is_empty() {
        "unknown camera"
    } else {
        camera
    };
    // A CCD's frames record no ISO: their temperature and gain say which
    // setting the calibration is of.
    let gain = data
        .ptc_fit
        .filter(|(k, _)| k.is_finite() && *k > 0.0)
        .map(|(k, _)| format!("K {} DN/e⁻", fmt_sig(k, 4)));
    let temperature = data.temperature_c.map(|t| format!("{t:.1} °C"));
    match (data.iso, temperature, gain) {
        (Some(iso), _, _) => format!("{camera}, ISO {iso}"),
        (None, Some(t), Some(k)) => format!("{camera}, {t}, {k}"),
        (None, Some(t), None) => format!("{camera}, {t}"),
        (None, None, Some(k)) => format!("{camera}, {k}"),
        (None, None, None) => format!("{camera}, no ISO, temperature or gain recorded"),
    }
}

/// Numbers in plot labels: a fixed number of significant digits reads better
/// than Rust's shortest round-trip form ("0.30000000000000004").
fn fmt_sig(v: f64, digits: usize) -> String {
    if !v.is_finite() {
        return format!("{v}");
    }
    if v == 0.0 {
        return "0".to_string();
    }
    let mag = v.abs().log10().floor() as i32;
    if !(-3..5).contains(&mag) {
        let s = format!("{:.*e}", digits.saturating_sub(1), v);
        return match s.split_once('e') {
            Some((m, e)) => format!("{}e{e}", trim_zeros(m)),
            None => s,
        };
    }
    let decimals = (digits as i32 - 1 - mag).max(0) as usize;
    trim_zeros(&format!("{v:.decimals$}")).to_string()
}

fn trim_zeros(s: &str) -> &str {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        s
    }
}

/// Pixel counts of a multi-megapixel sensor: "2.5M" reads at a glance where
/// "2.50e6" or "2500000" needs counting digits.
fn fmt_count(v: &f64) -> String {
    let a = v.abs();
    let (scaled, suffix) = if a >= 1e9 {
        (v / 1e9, "G")
    } else if a >= 1e6 {
        (v / 1e6, "M")
    } else if a >= 1e4 {
        (v / 1e3, "k")
    } else {
        (*v, "")
    };
    format!("{}{suffix}", fmt_sig(scaled, 3))
}

fn fmt_tick(v: &f64) -> String {
    fmt_sig(*v, 3)
}

/// Percentiles by nearest rank over finite values only: non-finite pixels
/// (dead pixels, divisions by zero in the estimators) must not decide the
/// display range or the median. `values` is reordered.
fn percentiles(values: &mut [f32], qs: &[f64]) -> Vec<f64> {
    if values.is_empty() {
        return vec![f64::NAN; qs.len()];
    }
    let n = values.len();
    qs.iter()
        .map(|&q| {
            let idx = ((q.clamp(0.0, 1.0) * (n - 1) as f64).round() as usize).min(n - 1);
            let (_, v, _) = values.select_nth_unstable_by(idx, f32::total_cmp);
            *v as f64
        })
        .collect()
}

fn finite_values(a: &ArrayView3<f32>) -> Vec<f32> {
    a.iter().copied().filter(|v| v.is_finite()).collect()
}

/// A display range that is never empty, so plotters never divides by zero
/// when every value is the same.
fn widen(lo: f64, hi: f64) -> (f64, f64) {
    if hi > lo {
        (lo, hi)
    } else {
        let pad = if lo == 0.0 { 0.5 } else { lo.abs() * 0.05 };
        (lo - pad, hi + pad)
    }
}

/// A log axis's range spread to at least `decades` decades about its
/// geometric centre: a log axis labels powers of ten and their multiples,
/// so one flat level (a range of a factor 2.6 with its margins) would get
/// almost no tick labels.
fn log_span(lo: f64, hi: f64, decades: f64) -> (f64, f64) {
    let want = 10f64.powf(decades);
    let ratio = hi / lo;
    if lo > 0.0 && ratio.is_finite() && ratio < want {
        let f = (want / ratio).sqrt();
        (lo / f, hi * f)
    } else {
        (lo, hi)
    }
}

// ---------------------------------------------------------------------- PTC

/// A log axis whose labels [`log_ticks`] chose.
type LogAxis = WithKeyPoints<LogCoord<f64>>;

/// A log-log chart on a report bitmap.
type LogLogChart<'a, 'b> = ChartContext<'a, BitMapBackend<'b>, Cartesian2d<LogAxis, LogAxis>>;

/// The fewest labels a log axis gets from [`log_ticks`].
const MIN_LOG_LABELS: usize = 5;

/// Labelled and grid values of a log axis over `lo..hi`: the labels are
/// the multiples m x 10^k in range of the first set of m (1; 1, 2, 5; 1,
/// 2, 3, 5; 1 .. 9) that gives [`MIN_LOG_LABELS`], the grid every 1 .. 9
/// multiple. plotters' own choice labels one to three values on an axis of
/// one or two decades (a CCD's flats at one level, a camera's at three).
fn log_ticks(lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    let multiples = |ms: &[f64]| -> Vec<f64> {
        if !(lo > 0.0 && hi > lo && (hi / lo).is_finite()) {
            return Vec::new();
        }
        let (k0, k1) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
        (k0..=k1)
            .flat_map(|k| ms.iter().map(move |m| m * 10f64.powi(k)))
            .filter(|v| (lo..=hi).contains(v))
            .collect()
    };
    let all: Vec<f64> = (1..=9).map(f64::from).collect();
    let labels = [&[1.0][..], &[1.0, 2.0, 5.0], &[1.0, 2.0, 3.0, 5.0], &all]
        .iter()
        .map(|ms| multiples(ms))
        .find(|v| v.len() >= MIN_LOG_LABELS)
        .unwrap_or_else(|| multiples(&all));
    (labels, multiples(&all))
}

/// A log axis over `lo..hi` labelled by [`log_ticks`].
fn log_axis(lo: f64, hi: f64) -> LogAxis {
    let (labels, grid) = log_ticks(lo, hi);
    (lo..hi)
        .log_scale()
        .with_key_points(labels)
        .with_light_points(grid)
}

/// The chart of the plots against mean signal (photon transfer, SNR):
/// log-log over `x` and `y`, the mesh drawn in the report's style with
/// `y_desc` on the vertical axis.
fn log_log_chart<'a, 'b>(
    root: &'a Area<'b>,
    caption: &str,
    (x_lo, x_hi): (f64, f64),
    (y_lo, y_hi): (f64, f64),
    y_desc: &str,
) -> Result<LogLogChart<'a, 'b>, Box<dyn std::error::Error>> {
    let mut chart = REPORT
        .frame(root, caption)
        .build_cartesian_2d(log_axis(x_lo, x_hi), log_axis(y_lo, y_hi))?;
    REPORT
        .mesh(&mut chart, "mean signal [DN]", y_desc)
        .x_label_formatter(&fmt_tick)
        .y_label_formatter(&fmt_tick)
        .draw()?;
    Ok(chart)
}

/// Log-log axes, because flat levels are normally spaced geometrically
/// (exposure doubled per level): on linear axes the low-signal points, where
/// read noise and the fit intercept matter, collapse into one corner. The
/// straight shot-noise line still reads as slope one and K is annotated.
fn ptc_section(dir: &Path, data: &ReportData, title: &str) -> Result<Section, ReportError> {
    const HEADING: &str = "Photon transfer curve";
    let all = &data.ptc_points;
    if all.is_empty() {
        return Ok(Section::skipped(
            HEADING,
            PTC_PNG,
            "Skipped: no photon-transfer points (no flat-field frames were given).".to_string(),
        ));
    }
    let pts: Vec<(f64, f64)> = all
        .iter()
        .filter(|p| p.mean_dn.is_finite() && p.var_dn2.is_finite())
        .filter(|p| p.mean_dn > 0.0 && p.var_dn2 > 0.0)
        .map(|p| (p.mean_dn, p.var_dn2))
        .collect();
    let dropped = all.len() - pts.len();
    if pts.is_empty() {
        return Ok(Section::skipped(
            HEADING,
            PTC_PNG,
            format!(
                "Skipped: none of the {} photon-transfer points has a positive, finite mean and variance.",
                all.len()
            ),
        ));
    }
    let fit = data.ptc_fit.filter(|(k, b)| k.is_finite() && b.is_finite());
    let (x, y) = ptc_axes(&pts, fit);
    let path = dir.join(PTC_PNG);
    let caption = format!("Photon transfer: {title}");
    render_png(&path, (PLOT_W, PLOT_H), |root| {
        draw_ptc(root, &caption, &pts, fit, x, y)
    })?;
    let text = ptc_text(fit, dropped);
    Ok(Section::written(HEADING, PTC_PNG, path, text))
}

/// The photon-transfer axes, (x_lo, x_hi) and (y_lo, y_hi): the points and
/// the fit line at both ends, a fifth of a decade of margin on each side to
/// keep end points off the frame, and at least one decade each way to keep
/// the axes labelled.
fn ptc_axes(pts: &[(f64, f64)], fit: Option<(f64, f64)>) -> ((f64, f64), (f64, f64)) {
    let (mut x_lo, mut x_hi) = min_max(pts.iter().map(|p| p.0));
    let (mut y_lo, mut y_hi) = min_max(pts.iter().map(|p| p.1));
    if let Some((k, b)) = fit {
        for x in [x_lo, x_hi] {
            let y = k * x + b;
            if y > 0.0 {
                y_lo = y_lo.min(y);
                y_hi = y_hi.max(y);
            }
        }
    }
    x_lo /= 1.6;
    x_hi *= 1.6;
    y_lo /= 1.6;
    y_hi *= 1.6;
    (log_span(x_lo, x_hi, 1.0), log_span(y_lo, y_hi, 1.0))
}

/// The photon-transfer chart: the fit line (if any) under the flat levels'
/// points, the legend, and a note where no fit was given.
fn draw_ptc(
    root: &Area,
    caption: &str,
    pts: &[(f64, f64)],
    fit: Option<(f64, f64)>,
    (x_lo, x_hi): (f64, f64),
    (y_lo, y_hi): (f64, f64),
) -> PlotResult {
    let mut chart = log_log_chart(
        root,
        caption,
        (x_lo, x_hi),
        (y_lo, y_hi),
        "temporal variance [DN^2]",
    )?;
    if let Some((k, b)) = fit {
        // Sampled densely because a line with an intercept is curved on
        // log axes; samples where the model variance is not positive have
        // no place on a log axis and are left out.
        let n = 200;
        let line: Vec<(f64, f64)> = (0..=n)
            .map(|i| {
                let t = i as f64 / n as f64;
                x_lo * (x_hi / x_lo).powf(t)
            })
            .map(|x| (x, k * x + b))
            .filter(|&(_, y)| y >= y_lo && y <= y_hi)
            .collect();
        let label = format!(
            "fit var = K·mean + b:  K = {} DN/e⁻ ({} e⁻/DN),  b = {} DN²",
            fmt_sig(k, 4),
            electrons_per_dn(k),
            fmt_sig(b, 4)
        );
        let anno = chart.draw_series(LineSeries::new(line, curve(FIT)))?;
        line_key(anno, label, curve(FIT));
    }
    let anno = chart.draw_series(pts.iter().map(|&p| REPORT.point(p)))?;
    REPORT.point_key(anno, format!("flat levels ({})", pts.len()));
    REPORT.legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
    if fit.is_none() {
        root.draw(&Text::new(
            "no fit given",
            (PLOT_W as i32 - 220, PLOT_H as i32 - 120),
            note_style(18, FIT),
        ))?;
    }
    Ok(())
}

/// The conversion factor 1/K in e⁻/DN, "inf" for a gain of zero.
fn electrons_per_dn(k: f64) -> String {
    if k != 0.0 {
        fmt_sig(1.0 / k, 4)
    } else {
        "inf".to_string()
    }
}

/// summary.md's caption of the photon-transfer curve: how to read it, the
/// fit, and how many points were left out.
fn ptc_text(fit: Option<(f64, f64)>, dropped: usize) -> String {
    let mut text = String::from(
        "Temporal variance against mean signal per flat level, log-log. In the \
         shot-noise regime the points follow var = K·mean + b; the slope K is the \
         system gain.",
    );
    match fit {
        Some((k, b)) => {
            let _ = write!(
                text,
                " Fit: K = {} DN/e⁻ ({} e⁻/DN), intercept b = {} DN².",
                fmt_sig(k, 4),
                electrons_per_dn(k),
                fmt_sig(b, 4)
            );
        }
        None => text.push_str(
            " No fit was given (a photon-transfer fit takes flats at two or more levels).",
        ),
    }
    if dropped > 0 {
        let _ = write!(
            text,
            " {dropped} point(s) with non-positive or non-finite values are not shown."
        );
    }
    text
}

/// The SNR curves that follow from a photon-transfer fit (K, b) and the
/// temporal noise variance without light, `dark` (DN²).
struct SnrModel {
    fit: Option<(f64, f64)>,
    dark: f64,
}

impl SnrModel {
    /// The model SNR(mu) = mu / sqrt(K mu + b + dark) at mean signal `x`.
    fn model(&self, x: f64) -> Option<f64> {
        let dark = self.dark;
        self.fit
            .map(|(k, b)| x / (k * x + b + dark).max(f64::MIN_POSITIVE).sqrt())
    }

    /// The ideal sensor's SNR sqrt(mu / K), shot noise alone, at `x`.
    fn ideal(&self, x: f64) -> Option<f64> {
        self.fit.map(|(k, _)| (x / k).sqrt())
    }
}

/// EMVA 1288's SNR curve: each flat level's SNR, its mean over the square
/// root of its shot variance plus the dark variance; the model SNR(mu) =
/// mu / sqrt(K mu + b + dark) from the photon-transfer fit; and the ideal
/// sensor's sqrt(mu / K), shot noise alone, for reference; log-log against
/// the mean signal.
fn snr_section(dir: &Path, data: &ReportData, title: &str) -> Result<Section, ReportError> {
    const HEADING: &str = "Signal-to-noise ratio";
    let dark = data.dark_var_dn2.max(0.0);
    let pts: Vec<(f64, f64)> = data
        .ptc_points
        .iter()
        .filter(|p| p.mean_dn > 0.0 && p.var_dn2.is_finite() && p.var_dn2 + dark > 0.0)
        .map(|p| (p.mean_dn, p.mean_dn / (p.var_dn2 + dark).sqrt()))
        .collect();
    if pts.is_empty() {
        return Ok(Section::skipped(
            HEADING,
            SNR_PNG,
            "Skipped: no flat level with a positive signal.".to_string(),
        ));
    }
    let snr = SnrModel {
        fit: data
            .ptc_fit
            .filter(|(k, b)| k.is_finite() && *k > 0.0 && b.is_finite()),
        dark,
    };
    let (x_lo, x_hi) = min_max(pts.iter().map(|p| p.0));
    let (x_lo, x_hi) = log_span(x_lo / 4.0, x_hi * 2.0, 1.0);
    let mut ys: Vec<f64> = pts.iter().map(|p| p.1).collect();
    for x in [x_lo, x_hi] {
        ys.extend(snr.model(x));
        ys.extend(snr.ideal(x));
    }
    let (y_lo, y_hi) = min_max(ys.into_iter().filter(|y| *y > 0.0));
    let (y_lo, y_hi) = log_span(y_lo / 1.6, y_hi * 1.6, 1.0);
    let path = dir.join(SNR_PNG);
    let caption = format!("SNR: {title}");
    render_png(&path, (PLOT_W, PLOT_H), |root| {
        draw_snr(root, &caption, &pts, &snr, (x_lo, x_hi), (y_lo, y_hi))
    })?;
    Ok(Section::written(HEADING, SNR_PNG, path, snr_text(&snr)))
}

/// The SNR chart: the model and the shot-noise limit (with a fit) under
/// the flat levels' points, and the legend.
fn draw_snr(
    root: &Area,
    caption: &str,
    pts: &[(f64, f64)],
    snr: &SnrModel,
    (x_lo, x_hi): (f64, f64),
    (y_lo, y_hi): (f64, f64),
) -> PlotResult {
    let mut chart = log_log_chart(root, caption, (x_lo, x_hi), (y_lo, y_hi), "SNR")?;
    let xs: Vec<f64> = (0..=200)
        .map(|i| x_lo * (x_hi / x_lo).powf(i as f64 / 200.0))
        .collect();
    if let Some((k, _)) = snr.fit {
        let sampled = |f: &dyn Fn(f64) -> Option<f64>| -> Vec<(f64, f64)> {
            xs.iter()
                .filter_map(|&x| f(x).map(|y| (x, y)))
                .filter(|&(_, y)| y >= y_lo && y <= y_hi)
                .collect()
        };
        let model = sampled(&|x| snr.model(x));
        let anno = chart.draw_series(LineSeries::new(model, curve(FIT)))?;
        line_key(
            anno,
            "model: mean / sqrt(K·mean + b + dark variance)",
            curve(FIT),
        );
        let ideal = sampled(&|x| snr.ideal(x));
        let anno = chart.draw_series(LineSeries::new(ideal, thin_curve(REFERENCE)))?;
        let label = format!("shot noise alone: sqrt(mean / K), K = {}", fmt_sig(k, 4));
        line_key(anno, label, thin_curve(REFERENCE));
    }
    let anno = chart.draw_series(pts.iter().map(|&p| REPORT.point(p)))?;
    REPORT.point_key(anno, format!("flat levels ({})", pts.len()));
    REPORT.legend(&mut chart, SeriesLabelPosition::UpperLeft)
}

/// summary.md's caption of the SNR plot. It names only the lines drawn:
/// without a photon-transfer fit (one flat level) there is no model and no
/// shot-noise line.
fn snr_text(snr: &SnrModel) -> String {
    match snr.fit {
        Some(_) => format!(
            "SNR of each flat level (mean over the temporal noise, {} DN² of it without light), \
             log-log, with the model from the photon-transfer fit and the shot-noise limit; at \
             low signal the dark noise pulls the levels below the shot-noise line.",
            fmt_sig(snr.dark, 4)
        ),
        None => format!(
            "SNR of each flat level (mean over the temporal noise, {} DN² of it without light), \
             log-log. No model or shot-noise line: they need a photon-transfer fit, which takes \
             flats at two or more levels.",
            fmt_sig(snr.dark, 4)
        ),
    }
}

fn min_max(it: impl Iterator<Item = f64>) -> (f64, f64) {
    it.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    })
}

// --------------------------------------------------------------- histograms

/// One histogram drawn on shared bins.
struct HistSeries {
    label: String,
    color: RGBColor,
    counts: Vec<u64>,
    median: f64,
}

/// Equal-width bins over [lo, hi]; values outside are counted separately so
/// the caption can say how many were left out instead of silently piling
/// them into the edge bins.
fn bin(values: &[f32], lo: f64, hi: f64, n_bins: usize) -> (Vec<u64>, usize, usize) {
    let mut counts = vec![0u64; n_bins];
    let (mut below, mut above) = (0, 0);
    let width = (hi - lo) / n_bins as f64;
    for &v in values {
        let v = v as f64;
        if v < lo {
            below += 1;
        } else if v > hi {
            above += 1;
        } else {
            let i = (((v - lo) / width) as usize).min(n_bins - 1);
            counts[i] += 1;
        }
    }
    (counts, below, above)
}

/// Enough bins to show shape, few enough that small test maps do not turn
/// into a comb.
fn bin_count(n: usize) -> usize {
    ((n as f64).sqrt() as usize).clamp(10, 120)
}

struct HistSpec<'s> {
    caption: String,
    x_desc: &'s str,
    lo: f64,
    hi: f64,
    series: &'s [HistSeries],
    unit: &'s str,
    /// Log counts show the rare tail (RTS and hot pixels) next to the bulk.
    log_y: bool,
    note: Option<String>,
}

/// The histogram chart: count axis (log or linear) to fit the tallest bar,
/// the bars and medians, and the note about values not shown under the
/// x-axis title.
fn draw_histogram(root: &Area, spec: &HistSpec) -> PlotResult {
    let max_count = spec
        .series
        .iter()
        .flat_map(|s| s.counts.iter().copied())
        .max()
        .unwrap_or(1)
        .max(1) as f64;
    let mut builder = REPORT.frame(root, &spec.caption);
    // Room under the x-axis title for the note about values not shown.
    builder.margin_bottom(if spec.note.is_some() { 40 } else { 20 });
    if spec.log_y {
        // Bars start just below one so a single-pixel bin is still visible.
        let mut chart =
            builder.build_cartesian_2d(spec.lo..spec.hi, (0.7..max_count * 2.0).log_scale())?;
        histogram_body(&mut chart, spec, 0.7)?;
    } else {
        let mut chart = builder.build_cartesian_2d(spec.lo..spec.hi, 0.0..max_count * 1.08)?;
        histogram_body(&mut chart, spec, 0.0)?;
    }
    if let Some(note) = &spec.note {
        root.draw(&Text::new(
            note.clone(),
            (110, PLOT_H as i32 - 30),
            quiet_note_style(15),
        ))?;
    }
    Ok(())
}

/// The mesh, the bars and the medians of a histogram whose bars start at
/// `base` (where the count axis starts), and the legend.
fn histogram_body<'a, Y>(
    chart: &mut ChartContext<'a, BitMapBackend<'a>, Cartesian2d<RangedCoordf64, Y>>,
    spec: &HistSpec,
    base: f64,
) -> PlotResult
where
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let y_top = chart.y_range().end;
    REPORT
        .mesh(chart, spec.x_desc, "pixels")
        .x_label_formatter(&fmt_tick)
        .y_label_formatter(&fmt_count)
        .draw()?;
    let overlay = spec.series.len() > 1;
    for s in spec.series {
        let n_bins = s.counts.len();
        let width = (spec.hi - spec.lo) / n_bins as f64;
        let fill = bars(s.color, overlay);
        let rects = s
            .counts
            .iter()
            .enumerate()
            .filter(|(_, &c)| c > 0)
            .map(|(i, &c)| {
                let x0 = spec.lo + i as f64 * width;
                Rectangle::new([(x0, base), (x0 + width, c as f64)], fill)
            });
        let anno = chart.draw_series(rects)?;
        swatch_key(anno, s.label.clone(), s.color);
    }
    median_lines(chart, spec, base, y_top, overlay)?;
    REPORT.legend(chart, legend_corner(spec.series))
}

/// Each series' median as a dashed vertical line, named in the legend.
fn median_lines<'a, Y>(
    chart: &mut ChartContext<'a, BitMapBackend<'a>, Cartesian2d<RangedCoordf64, Y>>,
    spec: &HistSpec,
    base: f64,
    y_top: f64,
    overlay: bool,
) -> PlotResult
where
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    for s in spec.series {
        if !s.median.is_finite() {
            continue;
        }
        let style = marker(if overlay { s.color } else { FIT });
        let line = vec![(s.median, base), (s.median, y_top)];
        let anno = chart.draw_series(dashed(line, style))?;
        let label = format!(
            "median {}{} {}",
            if overlay {
                format!("({}) ", short_label(&s.label))
            } else {
                String::new()
            },
            fmt_sig(s.median, 4),
            spec.unit
        );
        swatch_line_key(anno, label, style);
    }
    Ok(())
}

/// Put the legend over the half of the plot where the tallest bar is not,
/// so it never hides the mode (R² piles up near 1 on the right, read noise
/// near zero on the left).
fn legend_corner(series: &[HistSeries]) -> SeriesLabelPosition {
    let peak = series
        .iter()
        .filter_map(|s| {
            let (i, &c) = s.counts.iter().enumerate().max_by_key(|(_, &c)| c)?;
            Some((c, i as f64 / s.counts.len().max(1) as f64))
        })
        .max_by(|a, b| a.0.cmp(&b.0))
        .map(|(_, pos)| pos)
        .unwrap_or(0.0);
    if peak > 0.5 {
        SeriesLabelPosition::UpperLeft
    } else {
        SeriesLabelPosition::UpperRight
    }
}

/// Legend text for a median line: the series label up to its first space
/// or colon, so two medians are told apart without repeating the formula.
fn short_label(label: &str) -> &str {
    label.split([' ', ':']).next().unwrap_or(label)
}

fn sigma_hist_section(dir: &Path, data: &ReportData, title: &str) -> Result<Section, ReportError> {
    const HEADING: &str = "Read-noise histogram";
    let mut values = finite_values(&data.sigma_read);
    let total = data.sigma_read.len();
    if values.is_empty() {
        return Ok(Section::skipped(
            HEADING,
            SIGMA_HIST_PNG,
            if total == 0 {
                "Skipped: the read-noise map is empty.".to_string()
            } else {
                format!("Skipped: none of the {total} read-noise values is finite.")
            },
        ));
    }
    let non_finite = total - values.len();
    // The top 0.05 % (hot and RTS pixels) can be orders of magnitude above the
    // bulk; letting them set the axis would squash the bulk into one bar.
    let p = percentiles(&mut values, &[0.0, 0.5, 0.9995]);
    let (lo, hi) = widen(p[0], p[2]);
    let n_bins = bin_count(values.len());
    let (counts, _, above) = bin(&values, lo, hi, n_bins);
    let series = [HistSeries {
        label: if data.mono {
            "pixels".to_string()
        } else {
            "R, G1, B, G2 pixels".to_string()
        },
        color: BARS,
        counts,
        median: data
            .read_sigma_median
            .filter(|m| m.is_finite())
            .unwrap_or(p[1]),
    }];
    let note = hist_note(above, hi, non_finite);
    let spec = HistSpec {
        caption: format!("Read noise: {title}"),
        x_desc: "temporal read noise sigma [DN]",
        lo,
        hi,
        series: &series,
        unit: "DN",
        log_y: true,
        note: note.clone(),
    };
    let path = dir.join(SIGMA_HIST_PNG);
    render_png(&path, (PLOT_W, PLOT_H), |root| draw_histogram(root, &spec))?;
    let mut text = format!(
        "Per-pixel temporal read noise over {}, log count axis so the \
         hot/RTS tail is visible next to the bulk. Median {} DN.",
        if data.mono {
            "every pixel"
        } else {
            "all four CFA planes"
        },
        fmt_sig(spec.series[0].median, 4)
    );
    // Said in summary.md, not under the plot (one line there).
    if data.read_sigma_median.is_some_and(|m| m.is_finite()) {
        let _ = write!(
            text,
            " The line is the true per-pixel sigma's median, corrected for the frames' sampling error, as the summary table states it; the bars are the per-pixel sample sigmas (their median {} DN).",
            fmt_sig(p[1], 4)
        );
    }
    if let Some(note) = note {
        let _ = write!(text, " Note: {note}.");
    }
    Ok(Section::written(HEADING, SIGMA_HIST_PNG, path, text))
}

/// The read-noise histogram's note: values above its axis, values not
/// finite (None when neither).
fn hist_note(above: usize, hi: f64, non_finite: usize) -> Option<String> {
    let mut note = Vec::new();
    if above > 0 {
        note.push(format!(
            "{above} pixel(s) above the 99.95th percentile ({} DN) not shown",
            fmt_sig(hi, 4)
        ));
    }
    if non_finite > 0 {
        note.push(format!("{non_finite} non-finite value(s) ignored"));
    }
    (!note.is_empty()).then(|| note.join("; "))
}

/// Both laws on one set of bins: the question the plot answers is which
/// law explains the dark signal of more pixels, which needs a shared axis.
fn dark_r2_section(dir: &Path, data: &ReportData, title: &str) -> Result<Section, ReportError> {
    const HEADING: &str = "Dark-current fit quality";
    let laws = dark_laws(data);
    if laws.is_empty() {
        return Ok(Section::skipped(
            HEADING,
            DARK_R2_HIST_PNG,
            "Skipped: no dark-current fits (no dark frames were given).".to_string(),
        ));
    }
    let mut vals: Vec<Vec<f32>> = laws.iter().map(|(_, _, a)| finite_values(a)).collect();
    let mut combined: Vec<f32> = vals.iter().flatten().copied().collect();
    if combined.is_empty() {
        return Ok(Section::skipped(
            HEADING,
            DARK_R2_HIST_PNG,
            "Skipped: the dark-current R² maps hold no finite values.".to_string(),
        ));
    }
    // R² of a fit through the origin is unbounded below; the worst 0.5 % of
    // pixels would otherwise stretch the axis far past where the laws differ.
    let p = percentiles(&mut combined, &[0.005, 1.0]);
    let lo = if p[1] > -1.0 { p[0].max(-1.0) } else { p[0] };
    let (lo, hi) = widen(lo, p[1]);
    let n_bins = bin_count(combined.len() / laws.len()).min(80);
    let mut series = Vec::new();
    let mut below_total = 0;
    for ((label, color, _), v) in laws.iter().zip(vals.iter_mut()) {
        let (counts, below, _) = bin(v, lo, hi, n_bins);
        below_total += below;
        let median = percentiles(v, &[0.5])[0];
        series.push(HistSeries {
            label: label.to_string(),
            color: *color,
            counts,
            median,
        });
    }
    let note = (below_total > 0).then(|| {
        format!(
            "{below_total} value(s) below R² = {} not shown",
            fmt_sig(lo, 3)
        )
    });
    let spec = HistSpec {
        caption: format!("Dark-current fit R²: {title}"),
        x_desc: "R² of the per-pixel dark-current fit",
        lo,
        hi,
        series: &series,
        unit: "",
        log_y: false,
        note: note.clone(),
    };
    let path = dir.join(DARK_R2_HIST_PNG);
    render_png(&path, (PLOT_W, PLOT_H), |root| draw_histogram(root, &spec))?;
    let text = dark_r2_text(&series, note);
    Ok(Section::written(HEADING, DARK_R2_HIST_PNG, path, text))
}

/// The dark-current laws that were fitted, each with its legend label
/// (naming the offset term when the fits carry one), its colour and its
/// R² map, the square-root law first.
fn dark_laws<'d>(data: &'d ReportData) -> Vec<(&'static str, RGBColor, &'d ArrayView3<'d, f32>)> {
    let (sqrt, linear) = if data.dark_offset {
        ("sqrt-law: y = a·√t + c", "linear: y = a·t + c")
    } else {
        ("sqrt-law: y = a·√t", "linear: y = a·t")
    };
    [
        (sqrt, FIRST_OF_TWO, &data.r2_sqrt),
        (linear, SECOND_OF_TWO, &data.r2_linear),
    ]
    .into_iter()
    .filter_map(|(l, c, a)| a.as_ref().map(|a| (l, c, a)))
    .collect()
}

/// summary.md's caption of the R² histogram: how to read it, each law's
/// median R², and the note about values not shown.
fn dark_r2_text(series: &[HistSeries], note: Option<String>) -> String {
    let mut text = String::from(
        "Per-pixel R² of the dark-signal fits against exposure time; the law whose \
         histogram sits closer to 1 describes this sensor better.",
    );
    for s in series {
        let _ = write!(text, " Median R² {} ({}).", fmt_sig(s.median, 4), s.label);
    }
    if let Some(note) = note {
        let _ = write!(text, " Note: {note}.");
    }
    text
}

// --------------------------------------------------------------------- maps

/// Plane indices (into R, G1, B, G2) for the 2x2 tiles in reading order:
/// the Bayer RGGB layout, so the tile position matches the CFA position.
const TILE_PLANES: [usize; 4] = [0, 1, 3, 2];

/// A grayscale mosaic, scaled between the 0.5th and 99.5th percentile so a
/// few hot pixels do not turn the rest of the map black. Percentiles use the
/// full-resolution data, striding only decides which pixels are drawn. A
/// monochrome sensor's planes are its 2x2 sub-lattices: they are put back
/// together into one picture of the sensor instead of four tiles.
fn map_section(
    dir: &Path,
    file: &'static str,
    heading: &'static str,
    what: &str,
    unit: &str,
    map: &ArrayView3<f32>,
    mono: bool,
) -> Result<Section, ReportError> {
    let (h, w) = (map.shape()[1], map.shape()[2]);
    if h == 0 || w == 0 {
        return Ok(Section::skipped(
            heading,
            file,
            format!("Skipped: the {what} map is empty ({h}x{w} per plane)."),
        ));
    }
    let mut values = finite_values(map);
    if values.is_empty() {
        return Ok(Section::skipped(
            heading,
            file,
            format!("Skipped: the {what} map holds no finite values."),
        ));
    }
    let non_finite = map.len() - values.len();
    let p = percentiles(&mut values, &[0.005, 0.995]);
    drop(values);
    let (lo, hi) = (p[0], p[1]);
    let mosaic = Mosaic::new(map, lo, hi, mono);
    let path = dir.join(file);
    mosaic.write(&path)?;
    let mut text = map_layout_text(what, unit, mono);
    if hi > lo {
        let _ = write!(
            text,
            " Black = {} {unit} (0.5th percentile), white = {} {unit} (99.5th percentile).",
            fmt_sig(lo, 4),
            fmt_sig(hi, 4)
        );
    } else {
        let _ = write!(
            text,
            " The map is uniform at {} {unit} and shown mid-gray.",
            fmt_sig(lo, 4)
        );
    }
    if mosaic.stride > 1 {
        let (th, tw) = mosaic.tile;
        let _ = write!(
            text,
            " Downsampled by striding, one pixel in {} along each axis \
             ({h}x{w} per plane shown as {th}x{tw}).",
            mosaic.stride
        );
    }
    if non_finite > 0 {
        let _ = write!(text, " {non_finite} non-finite pixel(s) are shown black.");
    }
    Ok(Section::written(heading, file, path, text))
}

/// A map of four planes as one grayscale picture, strided down so that it
/// is at most [`MAP_MAX_SIDE`] on a side.
struct Mosaic {
    /// 8-bit gray, row by row.
    gray: Vec<u8>,
    /// Width and height of the picture, pixels.
    size: (usize, usize),
    /// One pixel in `stride` along each axis is drawn.
    stride: usize,
    /// Height and width of one plane as drawn.
    tile: (usize, usize),
}

impl Mosaic {
    /// The planes of `map` (R, G1, B, G2) as 2x2 tiles in CFA position,
    /// or, for a `mono` sensor, interleaved back into the sensor's pixel
    /// grid; `lo` is drawn black and `hi` white (see [`to_gray`]).
    fn new(map: &ArrayView3<f32>, lo: f64, hi: f64, mono: bool) -> Self {
        let (h, w) = (map.shape()[1], map.shape()[2]);
        let stride = (2 * h.max(w)).div_ceil(MAP_MAX_SIDE).max(1);
        let (th, tw) = (h.div_ceil(stride), w.div_ceil(stride));
        let (out_w, out_h) = (2 * tw, 2 * th);
        let mut gray = vec![0u8; out_w * out_h];
        for (t, &plane) in TILE_PLANES.iter().enumerate() {
            let (oy, ox) = ((t / 2) * th, (t % 2) * tw);
            let view = map.slice(s![plane, ..;stride, ..;stride]);
            for ((y, x), &v) in view.indexed_iter() {
                let (gy, gx) = if mono {
                    (2 * y + t / 2, 2 * x + t % 2)
                } else {
                    (oy + y, ox + x)
                };
                gray[gy * out_w + gx] = to_gray(v, lo, hi);
            }
        }
        Mosaic {
            gray,
            size: (out_w, out_h),
            stride,
            tile: (th, tw),
        }
    }

    /// Encode as a grayscale PNG and write it atomically at `path`.
    fn write(&self, path: &Path) -> Result<(), ReportError> {
        let (w, h) = self.size;
        let png = encode_png(
            path,
            &self.gray,
            (w as u32, h as u32),
            image::ExtendedColorType::L8,
        )?;
        pgrf_core::write_atomic(path, &png)?;
        Ok(())
    }
}

/// The first sentence of a map's caption: what is shown, in which unit,
/// and where each plane is in the picture.
fn map_layout_text(what: &str, unit: &str, mono: bool) -> String {
    if mono {
        format!(
            "{} ({unit}) as grayscale, one pixel per photosite (monochrome sensor).",
            capitalize(what)
        )
    } else {
        format!(
            "{} ({unit}) as grayscale, the four CFA planes tiled 2x2: R top-left, G1 top-right, \
             G2 bottom-left, B bottom-right.",
            capitalize(what),
        )
    }
}

fn to_gray(v: f32, lo: f64, hi: f64) -> u8 {
    if !v.is_finite() {
        return 0;
    }
    if hi <= lo {
        // A flat map: mid-gray says "uniform" where black would say "low".
        return 128;
    }
    let t = ((v as f64 - lo) / (hi - lo)).clamp(0.0, 1.0);
    (t * 255.0).round() as u8
}

fn capitalize(s: &str) -> String {
    let mut c = s.chars();
    match c.next() {
        Some(f) => f.to_uppercase().chain(c).collect(),
        None => String::new(),
    }
}

// ------------------------------------------------------------------ summary

/// Cells come from free-form strings; a stray pipe or newline would break
/// the table for every row after it.
fn md_cell(s: &str) -> String {
    s.replace('|', "\\|")
        .split(['\n', '\r'])
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join(" ")
}

fn summary_markdown(title: &str, data: &ReportData, sections: &[Section]) -> String {
    let mut md = String::new();
    let _ = writeln!(md, "# Calibration report: {title}\n");
    if data.summary.is_empty() {
        md.push_str("_No summary quantities were given._\n\n");
    } else {
        md.push_str("| quantity | value | unit |\n|---|---|---|\n");
        for (q, v, u) in &data.summary {
            let _ = writeln!(md, "| {} | {} | {} |", md_cell(q), md_cell(v), md_cell(u));
        }
        md.push('\n');
    }
    md.push_str("## Plots\n\n");
    for s in sections {
        match &s.path {
            Some(_) => {
                let _ = writeln!(md, "- [{}]({})", s.heading, s.file);
            }
            None => {
                let _ = writeln!(md, "- {} (`{}`): not written", s.heading, s.file);
            }
        }
    }
    md.push('\n');
    for s in sections {
        let _ = writeln!(md, "### {}\n", s.heading);
        match &s.path {
            Some(_) => {
                let _ = writeln!(md, "{}\n", s.text);
                let _ = writeln!(md, "![{}]({})\n", s.heading, s.file);
            }
            None => {
                let _ = writeln!(md, "_{}_\n", s.text);
            }
        }
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("pgrf-report-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// Deterministic pseudo-random numbers without a dev-dependency.
    fn lcg(seed: &mut u64) -> f32 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*seed >> 40) as f32) / (1u64 << 24) as f32
    }

    fn maps(h: usize, w: usize) -> (Array3<f32>, Array3<f32>, Array3<f32>, Array3<f32>) {
        let mut seed = 7;
        let sigma = Array3::from_shape_fn((4, h, w), |(p, y, x)| {
            let base = 2.0 + 0.2 * p as f32 + 0.002 * (x + y) as f32;
            let v = base + 0.5 * lcg(&mut seed);
            if (x * 31 + y * 17) % 97 == 0 {
                v * 8.0 // hot/RTS tail
            } else {
                v
            }
        });
        let mut fixed = Array3::from_shape_fn((4, h, w), |(p, y, x)| {
            // column banding plus a gradient, so the map has visible structure
            (if x % 8 < 2 { 1.5 } else { 0.0 }) + 0.01 * y as f32 - 0.3 * p as f32
                + 0.3 * lcg(&mut seed)
        });
        fixed[[1, 3, 3]] = f32::NAN;
        fixed[[2, 4, 4]] = f32::INFINITY;
        let r2s = Array3::from_shape_fn((4, h, w), |_| 0.98 - 0.2 * lcg(&mut seed).powi(3));
        let mut r2l = Array3::from_shape_fn((4, h, w), |_| 0.9 - 0.6 * lcg(&mut seed).powi(2));
        r2l[[0, 0, 0]] = f32::NAN;
        r2l[[0, 0, 1]] = -40.0;
        (sigma, fixed, r2s, r2l)
    }

    fn summary_rows() -> Vec<(String, String, String)> {
        vec![
            ("system gain K".into(), "0.452".into(), "DN/e-".into()),
            ("temporal dark noise".into(), "2.31".into(), "DN".into()),
            ("DSNU".into(), "0.84".into(), "DN".into()),
            ("PRNU".into(), "0.61".into(), "%".into()),
            ("dark current".into(), "0.013".into(), "e-/s".into()),
        ]
    }

    fn ptc() -> Vec<PtcPoint> {
        let (k, b) = (0.452, 5.3);
        (0..10)
            .map(|i| {
                let m = 20.0 * 2f64.powi(i);
                PtcPoint {
                    mean_dn: m,
                    var_dn2: (k * m + b) * (1.0 + 0.04 * ((i * 7 % 5) as f64 - 2.0)),
                }
            })
            .collect()
    }

    fn assert_png(path: &Path, w: u32, h: u32) {
        let img = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert_eq!((img.width(), img.height()), (w, h), "{}", path.display());
        let px = img.to_luma8();
        let n = px.len() as f64;
        let mean = px.iter().map(|&v| v as f64).sum::<f64>() / n;
        let var = px.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / n;
        assert!(var > 1.0, "{} looks flat (variance {var})", path.display());
    }

    #[test]
    fn writes_full_report() {
        let dir = scratch("full");
        let (h, w) = (48, 64);
        let (sigma, fixed, r2s, r2l) = maps(h, w);
        let data = ReportData {
            camera: "Sony ILCE-7SM2".into(),
            iso: Some(3200),
            ptc_points: ptc(),
            ptc_fit: Some((0.452, 5.3)),
            sigma_read: sigma.view(),
            fixed_pattern: fixed.view(),
            r2_sqrt: Some(r2s.view()),
            r2_linear: Some(r2l.view()),
            dark_offset: false,
            dark_var_dn2: 30.0,
            read_sigma_median: None,
            temperature_c: None,
            mono: false,
            summary: summary_rows(),
        };
        let written = write_report(&dir, &data).unwrap();
        // Exactly the files REPORT_FILES promises callers (who check them
        // before a calibration runs): no more, no fewer.
        let names = REPORT_FILES;
        assert_eq!(written.len(), names.len());
        for n in names {
            let p = dir.join(n);
            assert!(p.is_file(), "{n} missing");
            assert!(written.contains(&p), "{n} not reported");
        }
        for n in [PTC_PNG, SIGMA_HIST_PNG, DARK_R2_HIST_PNG] {
            assert_png(&dir.join(n), PLOT_W, PLOT_H);
        }
        for n in [FIXED_PATTERN_PNG, SIGMA_MAP_PNG] {
            assert_png(&dir.join(n), 2 * w as u32, 2 * h as u32);
        }
        let md = std::fs::read_to_string(dir.join(SUMMARY_MD)).unwrap();
        assert!(md.contains("Sony ILCE-7SM2"), "{md}");
        assert!(md.contains("ISO 3200"), "{md}");
        assert!(md.contains("| quantity | value | unit |"), "{md}");
        for (q, v, u) in summary_rows() {
            let row = format!("| {q} | {v} | {u} |");
            assert!(md.contains(&row), "missing row {row}\n{md}");
        }
        for n in names.iter().filter(|n| n.ends_with(".png")) {
            assert!(md.contains(&format!("]({n})")), "no link to {n}\n{md}");
        }
        let leftovers: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".part"))
            .collect();
        assert!(leftovers.is_empty(), "temp files left: {leftovers:?}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn map_tiles_follow_cfa_layout_and_stride() {
        let dir = scratch("tiles");
        // Each plane constant at its index, so tile brightness reveals the plane.
        let (h, w) = (900, 1000);
        let map = Array3::from_shape_fn((4, h, w), |(p, _, _)| p as f32);
        let sec = map_section(&dir, SIGMA_MAP_PNG, "t", "test", "DN", &map.view(), false).unwrap();
        let img = image::open(sec.path.unwrap()).unwrap().to_luma8();
        // 2 * 1000 = 2000 px > 1600, so stride 2: tiles 450x500.
        assert_eq!((img.width(), img.height()), (1000, 900));
        let at = |x, y| img.get_pixel(x, y).0[0];
        assert_eq!(at(10, 10), 0, "R top-left");
        assert_eq!(at(510, 10), 85, "G1 top-right");
        assert_eq!(at(10, 460), 255, "G2 bottom-left");
        assert_eq!(at(510, 460), 170, "B bottom-right");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A monochrome map is the sensor itself: sub-lattice (0,0) at even
    /// rows and columns, (0,1) at even rows and odd columns, (1,1) and (1,0)
    /// on odd rows, as the packed planes hold them.
    #[test]
    fn mono_maps_interleave_the_sub_lattices() {
        let dir = scratch("monomap");
        let (h, w) = (6, 5);
        let map = Array3::from_shape_fn((4, h, w), |(p, _, _)| p as f32);
        let sec = map_section(&dir, SIGMA_MAP_PNG, "t", "test", "DN", &map.view(), true).unwrap();
        assert!(sec.text.contains("one pixel per photosite"), "{}", sec.text);
        let img = image::open(sec.path.unwrap()).unwrap().to_luma8();
        assert_eq!((img.width(), img.height()), (10, 12));
        let at = |x, y| img.get_pixel(x, y).0[0];
        for (y, x) in [(0, 0), (4, 6), (10, 8)] {
            assert_eq!(at(x, y), 0, "(0,0) at row {y} col {x}");
            assert_eq!(at(x + 1, y), 85, "(0,1)");
            assert_eq!(at(x + 1, y + 1), 170, "(1,1)");
            assert_eq!(at(x, y + 1), 255, "(1,0)");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A log axis of about a decade and a half (a CCD's flats at one level
    /// and the bias) gets five labels, not plotters' one to three; four
    /// decades get their powers of ten.
    #[test]
    fn log_axes_get_enough_labels() {
        let (labels, grid) = log_ticks(1300.0, 22000.0);
        assert_eq!(labels, vec![2000.0, 3000.0, 5000.0, 10000.0, 20000.0]);
        assert_eq!(grid.len(), 8 + 2, "{grid:?}");
        let (labels, _) = log_ticks(100.0, 1.0e6);
        assert_eq!(labels, vec![100.0, 1000.0, 1.0e4, 1.0e5, 1.0e6]);
        assert_eq!(log_ticks(5.0, 5.0), (vec![], vec![]));
    }

    /// A CCD's report is titled by its temperature and gain, not "ISO
    /// unknown".
    #[test]
    fn a_report_without_iso_is_titled_by_temperature_and_gain() {
        let z = Array3::<f32>::zeros((4, 2, 2));
        let mut data = ReportData {
            camera: "SBIG STL-1001".into(),
            iso: None,
            ptc_points: vec![],
            ptc_fit: Some((0.51736, 30.0)),
            sigma_read: z.view(),
            fixed_pattern: z.view(),
            r2_sqrt: None,
            r2_linear: None,
            dark_offset: false,
            dark_var_dn2: 30.0,
            read_sigma_median: Some(6.690),
            temperature_c: Some(-5.0),
            mono: true,
            summary: vec![],
        };
        assert_eq!(
            report_title(&data),
            "SBIG STL-1001, -5.0 °C, K 0.5174 DN/e⁻"
        );
        data.iso = Some(800);
        assert_eq!(report_title(&data), "SBIG STL-1001, ISO 800");
        // The histogram states the median the summary table states (the
        // corrected one), and the bars' own.
        let sigma = Array3::<f32>::from_elem((4, 8, 8), 6.436);
        data.sigma_read = sigma.view();
        let dir = scratch("corrected-median");
        write_report(&dir, &data).unwrap();
        let md = std::fs::read_to_string(dir.join(SUMMARY_MD)).unwrap();
        assert!(md.contains("Median 6.69 DN."), "{md}");
        assert!(md.contains("(their median 6.436 DN)"), "{md}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn empty_inputs_are_skipped_and_explained() {
        let dir = scratch("empty");
        let empty = Array3::<f32>::zeros((4, 0, 0));
        let nan = Array3::<f32>::from_elem((4, 2, 2), f32::NAN);
        let data = ReportData {
            camera: String::new(),
            iso: None,
            ptc_points: vec![],
            ptc_fit: None,
            sigma_read: nan.view(),
            fixed_pattern: empty.view(),
            r2_sqrt: None,
            r2_linear: None,
            dark_offset: false,
            dark_var_dn2: 30.0,
            read_sigma_median: None,
            temperature_c: None,
            mono: false,
            summary: vec![],
        };
        let written = write_report(&dir, &data).unwrap();
        assert_eq!(written, vec![dir.join(SUMMARY_MD)]);
        let md = std::fs::read_to_string(dir.join(SUMMARY_MD)).unwrap();
        assert!(md.contains("no ISO, temperature or gain recorded"), "{md}");
        assert!(md.contains("no photon-transfer points"), "{md}");
        assert!(md.contains("no dark frames"), "{md}");
        assert!(md.matches("Skipped").count() >= 5, "{md}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn ptc_without_fit_and_with_bad_points_still_plots() {
        let dir = scratch("nofit");
        let z = Array3::<f32>::zeros((4, 2, 2));
        let mut pts = ptc();
        pts.push(PtcPoint {
            mean_dn: -3.0,
            var_dn2: 4.0,
        });
        pts.push(PtcPoint {
            mean_dn: f64::NAN,
            var_dn2: 4.0,
        });
        let data = ReportData {
            camera: "x".into(),
            iso: Some(100),
            ptc_points: pts,
            ptc_fit: None,
            sigma_read: z.view(),
            fixed_pattern: z.view(),
            r2_sqrt: None,
            r2_linear: None,
            dark_offset: false,
            dark_var_dn2: 30.0,
            read_sigma_median: None,
            temperature_c: None,
            mono: false,
            summary: vec![],
        };
        let written = write_report(&dir, &data).unwrap();
        assert!(written.contains(&dir.join(PTC_PNG)));
        assert_png(&dir.join(PTC_PNG), PLOT_W, PLOT_H);
        assert_png(&dir.join(SNR_PNG), PLOT_W, PLOT_H);
        let md = std::fs::read_to_string(dir.join(SUMMARY_MD)).unwrap();
        assert!(md.contains("2 point(s)"), "{md}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// One flat level, no fit: both plots span at least a decade on each
    /// axis (so they carry tick labels), and the SNR text promises no line
    /// it does not draw.
    #[test]
    fn one_flat_level_plots_are_labelled_and_say_what_they_draw() {
        let (lo, hi) = log_span(1000.0 / 1.6, 1000.0 * 1.6, 1.0);
        assert!((hi / lo - 10.0).abs() < 1e-9 && ((lo * hi).sqrt() - 1000.0).abs() < 1e-9);
        assert_eq!(log_span(1.0, 500.0, 1.0), (1.0, 500.0));
        let dir = scratch("onelevel");
        let z = Array3::<f32>::zeros((4, 2, 2));
        let data = ReportData {
            camera: "x".into(),
            iso: None,
            ptc_points: vec![PtcPoint {
                mean_dn: 3000.0,
                var_dn2: 1400.0,
            }],
            ptc_fit: None,
            sigma_read: z.view(),
            fixed_pattern: z.view(),
            r2_sqrt: None,
            r2_linear: None,
            dark_offset: false,
            dark_var_dn2: 40.0,
            read_sigma_median: None,
            temperature_c: None,
            mono: true,
            summary: vec![],
        };
        write_report(&dir, &data).unwrap();
        assert_png(&dir.join(PTC_PNG), PLOT_W, PLOT_H);
        assert_png(&dir.join(SNR_PNG), PLOT_W, PLOT_H);
        let md = std::fs::read_to_string(dir.join(SUMMARY_MD)).unwrap();
        assert!(md.contains("No model or shot-noise line"), "{md}");
        assert!(!md.contains("with the model from"), "{md}");
        if std::env::var_os("PGRF_KEEP_REPORT").is_none() {
            let _ = std::fs::remove_dir_all(&dir);
        }
    }

    #[test]
    fn degenerate_inputs_do_not_panic() {
        let dir = scratch("degenerate");
        let one = Array3::<f32>::from_elem((4, 1, 1), 3.0);
        let bad_r2 = Array3::<f32>::from_elem((4, 1, 1), -5.0);
        let data = ReportData {
            camera: "x".into(),
            iso: Some(1),
            // One point and a fit that is negative everywhere on the plot.
            ptc_points: vec![PtcPoint {
                mean_dn: 10.0,
                var_dn2: 1.0,
            }],
            ptc_fit: Some((-1.0, -1.0)),
            sigma_read: one.view(),
            fixed_pattern: one.view(),
            r2_sqrt: Some(bad_r2.view()),
            r2_linear: None,
            dark_offset: false,
            dark_var_dn2: 30.0,
            read_sigma_median: None,
            temperature_c: None,
            mono: false,
            summary: vec![],
        };
        let written = write_report(&dir, &data).unwrap();
        assert_eq!(written.len(), 7, "{written:?}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn missing_dir_is_an_error() {
        let dir = scratch("missing").join("does-not-exist");
        let z = Array3::<f32>::zeros((4, 2, 2));
        let data = ReportData {
            camera: "x".into(),
            iso: None,
            ptc_points: vec![],
            ptc_fit: None,
            sigma_read: z.view(),
            fixed_pattern: z.view(),
            r2_sqrt: None,
            r2_linear: None,
            dark_offset: false,
            dark_var_dn2: 30.0,
            read_sigma_median: None,
            temperature_c: None,
            mono: false,
            summary: vec![],
        };
        let err = write_report(&dir, &data).unwrap_err();
        assert!(matches!(err, ReportError::MissingDir(_)), "{err}");
        let msg = err.to_string();
        assert!(
            msg.contains("does not exist") && !msg.contains('\n'),
            "{msg}"
        );
        assert!(!dir.exists());
    }

    #[test]
    fn wrong_plane_count_is_an_error() {
        let dir = scratch("planes");
        let z3 = Array3::<f32>::zeros((3, 2, 2));
        let z = Array3::<f32>::zeros((4, 2, 2));
        let data = ReportData {
            camera: "x".into(),
            iso: None,
            ptc_points: vec![],
            ptc_fit: None,
            sigma_read: z3.view(),
            fixed_pattern: z.view(),
            r2_sqrt: None,
            r2_linear: None,
            dark_offset: false,
            dark_var_dn2: 30.0,
            read_sigma_median: None,
            temperature_c: None,
            mono: false,
            summary: vec![],
        };
        let err = write_report(&dir, &data).unwrap_err().to_string();
        assert!(err.contains("sigma_read has 3 planes"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn percentiles_ignore_order_and_number_format_is_short() {
        let mut v = vec![5.0, 1.0, 3.0, 2.0, 4.0];
        assert_eq!(percentiles(&mut v, &[0.0, 0.5, 1.0]), vec![1.0, 3.0, 5.0]);
        assert!(percentiles(&mut [], &[0.5])[0].is_nan());
        assert_eq!(fmt_sig(0.30000000000000004, 4), "0.3");
        assert_eq!(fmt_sig(1234.567, 4), "1235");
        assert_eq!(fmt_sig(0.4521, 3), "0.452");
        assert_eq!(fmt_sig(2.0e6, 3), "2e6");
        assert_eq!(fmt_sig(-2.5e-5, 3), "-2.5e-5");
        assert_eq!(fmt_count(&2.5e6), "2.5M");
        assert_eq!(fmt_count(&20000.0), "20k");
        assert_eq!(fmt_count(&100.0), "100");
        assert_eq!(md_cell("a|b\nc"), "a\\|b c");
    }
}
