//! Poisson-Gaussian camera profiles from the noise descriptions other
//! tools write: the DNG NoiseProfile tag (`--profile dng:FILE.dng`), and
//! tables of them over ISO ([`poisson_gaussian_table`]: darktable's
//! `noiseprofiles.json`, [`crate::darktable`]).
//!
//! Those describe noise as a variance S x + O of the signal x normalised to
//! [0, 1] (black 0, white 1). In pgrf's DN terms, on a scale of
//! `range` = white - black DN, a signal of x range DN has shot variance
//! K x range and read variance sigma^2, so
//!
//! K = S range and sigma = sqrt(O) range.
//!
//! That is all such a description holds: no row noise, no fixed pattern,
//! no heavy-tailed read noise. The profile made from it drives the
//! Poisson-Gaussian model (`--model pg`) exactly; ELD's and pgrf's models
//! run on it with those components at zero and a near-Gaussian read noise
//! of the same standard deviation (a Tukey lambda of shape 0.14 whose scale
//! is sigma / 1.4527, since that shape's standard deviation is 1.4527 times
//! its scale).

use crate::error::{NoiseError, Result};
use crate::profile::{CameraProfile, EldFits, IsoPoint, LogFit};
use std::path::Path;

/// Tukey lambda of a near-Gaussian read noise (0.14 matches the normal
/// distribution's shape most closely), for the models that draw one.
const GAUSSIAN_LAMBDA: f64 = 0.14;

/// Standard deviation of the Tukey-lambda distribution of shape
/// [`GAUSSIAN_LAMBDA`] and scale 1: sqrt((2 / l^2) (1 / (1 + 2 l) -
/// Gamma(l + 1)^2 / Gamma(2 l + 2))) at l = 0.14. A read noise of standard
/// deviation sigma drawn from that shape has scale sigma / TUKEY_SD.
const TUKEY_SD: f64 = 1.452_686_140_298_209;

/// Noise of one camera at one ISO in the normalised Poisson-Gaussian form.
#[derive(Clone, Debug, PartialEq)]
pub struct PgNoise {
    /// The ISO it holds at.
    pub iso: u32,
    /// S: variance per unit of normalised signal.
    pub s: f64,
    /// O: variance without signal.
    pub o: f64,
    /// White - black, DN: the scale normalised signal refers to.
    pub range: f64,
    /// Black level, DN.
    pub black: f64,
}

/// One ISO of a Poisson-Gaussian table: variance S x + O at signal x
/// normalised to [0, 1].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PgRow {
    /// The ISO it holds at.
    pub iso: u32,
    /// S: variance per unit of normalised signal.
    pub s: f64,
    /// O: variance without signal.
    pub o: f64,
}

/// A single-ISO Poisson-Gaussian profile of `noise`, named `name`, of the
/// camera `make` `model`; `source` says where the numbers came from.
pub fn poisson_gaussian(
    name: &str,
    make: &str,
    model: &str,
    noise: &PgNoise,
    source: String,
) -> Result<CameraProfile> {
    let row = PgRow {
        iso: noise.iso,
        s: noise.s,
        o: noise.o,
    };
    poisson_gaussian_table(
        name,
        make,
        model,
        &[row],
        noise.range,
        Some(noise.black),
        source,
    )
}

/// A Poisson-Gaussian profile holding at the ISOs of `rows` (strictly
/// increasing), on the scale `range` = white - black DN, with black level
/// `black` DN (None: not known, and results are not clipped below black).
/// Between two rows, [`CameraProfile::params_at_iso`] interpolates K and
/// sigma linearly in log ISO; outside them it refuses. Without an ISO,
/// capture parameters are drawn as ELD draws them: ln K uniform over the
/// rows' gains, ln sigma from a least-squares line in ln K through the rows
/// with a read noise (sigma > 0), with the line's residual standard
/// deviation.
pub fn poisson_gaussian_table(
    name: &str,
    make: &str,
    model: &str,
    rows: &[PgRow],
    range: f64,
    black: Option<f64>,
    source: String,
) -> Result<CameraProfile> {
    let bad = |reason: String| NoiseError::Profile {
        name: name.to_string(),
        reason,
    };
    if rows.is_empty() {
        return Err(bad("the noise table is empty".into()));
    }
    let mut per_iso = Vec::with_capacity(rows.len());
    for &PgRow { iso, s, o } in rows {
        if !(s.is_finite() && s > 0.0 && o.is_finite() && o >= 0.0) {
            return Err(bad(format!(
                "the noise pair at ISO {iso} (S {s}, O {o}) needs S > 0 and O >= 0, both finite"
            )));
        }
        let k = s * range;
        let sigma = o.sqrt() * range;
        per_iso.push(IsoPoint {
            iso,
            k,
            tukey_lambda: GAUSSIAN_LAMBDA,
            sigma_tukey: sigma / TUKEY_SD,
            sigma_gauss: sigma,
            sigma_row: 0.0,
            black_level_error: 0.0,
        });
    }
    let (k_min, k_max) = per_iso.iter().fold((f64::INFINITY, 0.0f64), |(l, h), p| {
        (l.min(p.k), h.max(p.k))
    });
    let gauss_scale = read_fit(&per_iso);
    let tukey_scale = LogFit {
        bias: gauss_scale.bias - TUKEY_SD.ln(),
        ..gauss_scale.clone()
    };
    let p = CameraProfile {
        schema: 1,
        name: name.to_string(),
        make: make.to_string(),
        model: model.to_string(),
        source,
        units: "DN on the scale dn_range = white - black".into(),
        dn_range: range,
        black,
        k_per_iso: None,
        k_min,
        k_max,
        eld: EldFits {
            tukey_shapes: vec![GAUSSIAN_LAMBDA],
            tukey_scale,
            gauss_scale,
            row_scale: flat(0.0),
            color_bias: Vec::new(),
        },
        per_iso,
        dark_current: None,
    };
    p.checked().map_err(|fault| NoiseError::ProfileValues {
        name: name.to_string(),
        fault,
    })
}

/// ln(sigma) = slope ln(K) + bias through the rows with a read noise, by
/// least squares; a constant (the geometric mean) when fewer than two
/// distinct gains have one.
fn read_fit(rows: &[IsoPoint]) -> LogFit {
    let pts: Vec<(f64, f64)> = rows
        .iter()
        .filter(|p| p.sigma_gauss > 0.0)
        .map(|p| (p.k.ln(), p.sigma_gauss.ln()))
        .collect();
    let n = pts.len() as f64;
    if pts.is_empty() {
        return flat(0.0);
    }
    let mx = pts.iter().map(|p| p.0).sum::<f64>() / n;
    let my = pts.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    if pts.len() < 2 || sxx <= 1e-12 {
        return flat(my.exp());
    }
    let slope = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum::<f64>() / sxx;
    let bias = my - slope * mx;
    let sigma = if pts.len() > 2 {
        let ss: f64 = pts.iter().map(|p| (p.1 - slope * p.0 - bias).powi(2)).sum();
        (ss / (n - 2.0)).sqrt()
    } else {
        0.0
    };
    LogFit { slope, bias, sigma }
}

/// A scale that does not depend on the gain (1e-12 DN for none).
fn flat(v: f64) -> LogFit {
    LogFit {
        slope: 0.0,
        bias: v.max(1e-12).ln(),
        sigma: 0.0,
    }
}

/// The profile in a DNG's NoiseProfile tag, at the file's ISO: `spec` is
/// the path after `dng:`. Per-plane pairs are averaged (pgrf's models have
/// one gain for all planes; the spread is said in the profile's source).
pub fn from_dng(spec: &str) -> Result<CameraProfile> {
    let name = format!("dng:{spec}");
    let bad = |reason: String| NoiseError::Profile {
        name: name.clone(),
        reason,
    };
    let path = Path::new(spec);
    // Read once: the decoder and the tag reader see the same bytes.
    let bytes = std::fs::read(path).map_err(|e| bad(e.to_string()))?;
    let frame = pgrf_raw::decode_bytes(path, &bytes, &Default::default())
        .map_err(|e| bad(e.to_string()))?;
    let planes = if frame.mono { 1 } else { 3 };
    let pairs = pgrf_raw::container::noise_profile(&bytes, planes)
        .map_err(|e| bad(e.to_string()))?
        .ok_or_else(|| bad("the file has no NoiseProfile tag (51041)".into()))?;
    let iso = frame.iso.ok_or_else(|| {
        bad("the file records no ISO, and its NoiseProfile holds at one ISO only".into())
    })?;
    let n = pairs.len() as f64;
    let mean = [0, 1].map(|i| pairs.iter().map(|p| p[i]).sum::<f64>() / n);
    let black = frame.black.iter().map(|&b| b as f64).sum::<f64>() / 4.0;
    let range = frame.white as f64 - black;
    let spread = if pairs.len() > 1 {
        let (lo, hi) = pairs.iter().fold((f64::INFINITY, 0.0f64), |(l, h), p| {
            (l.min(p[0]), h.max(p[0]))
        });
        format!(
            "; mean of {} planes' pairs (S from {lo:.4e} to {hi:.4e}): pgrf's models have one gain",
            pairs.len()
        )
    } else {
        String::new()
    };
    let noise = PgNoise {
        iso,
        s: mean[0],
        o: mean[1],
        range,
        black,
    };
    poisson_gaussian(
        &name,
        &frame.make,
        &frame.model,
        &noise,
        format!(
            "DNG NoiseProfile of {} at ISO {iso}: S {:.4e}, O {:.4e}{spread}",
            path.display(),
            mean[0],
            mean[1]
        ),
    )
}

/// What a loaded profile holds, for display (`pgrf profiles show`): every
/// DN value on the profile's scale `dn_range`.
#[derive(Clone, Debug, PartialEq)]
pub struct ProfileView {
    /// The profile's name.
    pub name: String,
    /// Camera maker.
    pub make: String,
    /// Camera model.
    pub model: String,
    /// Where the numbers come from, with their limits.
    pub source: String,
    /// white - black, DN: the scale of every DN value.
    pub dn_range: f64,
    /// Black level, DN, when known.
    pub black: Option<f64>,
    /// K = k_per_iso x ISO, when the profile states it.
    pub k_per_iso: Option<f64>,
    /// The range of system gain K (DN per electron) the profile covers.
    pub k_range: (f64, f64),
    /// The per-ISO table (empty when the profile has none).
    pub rows: Vec<ViewRow>,
    /// ELD's fits: ln(sigma) = slope ln(K) + bias + N(0, sd^2), as
    /// (slope, bias, sd), for the Gaussian read, Tukey read and row scales.
    pub fits: [(f64, f64, f64); 3],
    /// The Tukey-lambda shapes ELD's sampling draws from.
    pub tukey_shapes: Vec<f64>,
}

/// One ISO of a profile's table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewRow {
    /// The ISO.
    pub iso: u32,
    /// System gain, DN per electron.
    pub k: f64,
    /// Gaussian read-noise standard deviation, DN.
    pub sigma_gauss: f64,
    /// Tukey-lambda read-noise shape.
    pub tukey_lambda: f64,
    /// Tukey-lambda read-noise scale, DN.
    pub sigma_tukey: f64,
    /// Row-noise standard deviation, DN.
    pub sigma_row: f64,
    /// Mean offset of the dark level from the nominal black, DN.
    pub black_level_error: f64,
}

impl ProfileView {
    /// The profile's parameters as `pgrf profiles show` prints them: its
    /// ISO table (and gain law), or, without one, its gain range, fits and
    /// Tukey shapes.
    pub fn parameter_lines(&self) -> Vec<String> {
        if self.rows.is_empty() {
            self.fit_lines()
        } else {
            self.table_lines()
        }
    }

    fn table_lines(&self) -> Vec<String> {
        let mut lines = vec![
            format!("table     {} ISOs", self.rows.len()),
            format!(
                "  {:>7}  {:>11}  {:>15}  {:>12}  {:>16}  {:>14}  {:>12}",
                "ISO",
                "K (DN/e-)",
                "read sigma (DN)",
                "Tukey lambda",
                "Tukey scale (DN)",
                "row sigma (DN)",
                "black error"
            ),
        ];
        for r in &self.rows {
            lines.push(format!(
                "  {:>7}  {:>11.5}  {:>15.4}  {:>12.4}  {:>16.4}  {:>14.4}  {:>12.4}",
                r.iso,
                r.k,
                r.sigma_gauss,
                r.tukey_lambda,
                r.sigma_tukey,
                r.sigma_row,
                r.black_level_error
            ));
        }
        if let Some(k) = self.k_per_iso {
            lines.push(format!("gain      K = {k} x ISO DN/e-"));
        }
        lines
    }

    fn fit_lines(&self) -> Vec<String> {
        let mut lines = vec![format!(
            "gain      no ISO table: K {:.5}..{:.5} DN/e-, drawn with ln K uniform (omit --iso){}",
            self.k_range.0,
            self.k_range.1,
            self.k_per_iso
                .map(|k| format!("; K = {k} x ISO at a given --iso"))
                .unwrap_or_default()
        )];
        for (what, (slope, bias, sd)) in ["read (Gaussian)", "read (Tukey)", "row"]
            .iter()
            .zip(self.fits)
        {
            lines.push(format!(
                "fit       {what:<16} ln sigma = {slope:.4} ln K {bias:+.4}, residual sd {sd:.4}"
            ));
        }
        lines.push(format!(
            "shapes    {} Tukey lambdas, {:.3}..{:.3}",
            self.tukey_shapes.len(),
            self.tukey_shapes
                .iter()
                .cloned()
                .fold(f64::INFINITY, f64::min),
            self.tukey_shapes
                .iter()
                .cloned()
                .fold(f64::NEG_INFINITY, f64::max)
        ));
        lines
    }
}

/// What `p` holds.
pub fn view(p: &CameraProfile) -> ProfileView {
    let fit = |f: &LogFit| (f.slope, f.bias, f.sigma);
    ProfileView {
        name: p.name.clone(),
        make: p.make.clone(),
        model: p.model.clone(),
        source: p.source.clone(),
        dn_range: p.dn_range,
        black: p.black,
        k_per_iso: p.k_per_iso,
        k_range: (p.k_min, p.k_max),
        rows: p
            .per_iso
            .iter()
            .map(|r| ViewRow {
                iso: r.iso,
                k: r.k,
                sigma_gauss: r.sigma_gauss,
                tukey_lambda: r.tukey_lambda,
                sigma_tukey: r.sigma_tukey,
                sigma_row: r.sigma_row,
                black_level_error: r.black_level_error,
            })
            .collect(),
        fits: [
            fit(&p.eld.gauss_scale),
            fit(&p.eld.tukey_scale),
            fit(&p.eld.row_scale),
        ],
        tukey_shapes: p.eld.tukey_shapes.clone(),
    }
}
