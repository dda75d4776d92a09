//! The estimators: what each stack says about each pixel.
//!
//! All maps are packed `(4, H/2, W/2)`, in DN unless stated. Equations refer
//! to the paper and EMVA 1288; one function per estimator of the paper
//! (PAPER.md at the repository root lists them):
//!
//! - fixed pattern, per-pixel bias mean minus black: `fixed_pattern`;
//! - source-follower (read) sigma, sqrt(var - sigma_H^2): `read_sigma`;
//! - row noise sigma_H, apart from whole-frame offset drift:
//!   `PixelStats::row_and_frame_variance` (`crate::stats`);
//! - system gain K = Var / mean (eq. 3.15): `gain_var_mean`, and its
//!   regression over light levels (photon transfer): `photon_transfer`;
//! - dark signal, dark mean minus bias mean: `dark_signal`; its fit
//!   y = a g(t) (+ c), g(t) = sqrt(t) or t: `fit_dark_law`, the law chosen
//!   by `choose_dark_law`; E(N) = K2 E(N_RS), K2 = 1 + N_FP, as a rate in
//!   electrons: `dark_rate`.

use crate::error::{CalibError, Result};
use crate::ppcc::ppcc;
use crate::stack::{Group, Stack};
use ndarray::{Array3, Zip};
use pgrf_core::stats::{median_and_robust_sd, median_finite};
use pgrf_noise::DarkLaw;

/// From bias frames (shortest exposure, no light).
#[derive(Clone, Debug)]
pub struct BiasEstimate {
    /// Per-pixel mean minus the black level: the fixed-pattern offset.
    pub(crate) fixed_pattern: Array3<f32>,
    /// Per-pixel temporal mean (DN, black included).
    pub(crate) mean: Array3<f64>,
    /// Per-pixel temporal variance (row noise included).
    pub(crate) var: Array3<f64>,
    /// Source-follower sigma: sqrt(var - row variance).
    pub sigma_read: Array3<f32>,
    /// The median over pixels of the true source-follower sigma, DN:
    /// `read_sigma_median` (this module), not the median of `sigma_read` (which sits
    /// low by the sampling error of a few frames).
    pub read_sigma_median: f64,
    /// EMVA 1288's temporal dark noise sigma_y.dark, DN: `dark_noise_sigma` (this module).
    pub dark_noise_sigma: f64,
    pub(crate) row_sigma: f64,
    /// Standard deviation of the whole-frame offset from frame to frame, DN.
    pub(crate) frame_offset_sigma: f64,
    /// DSNU: spatial sd of the fixed pattern, temporal noise of the mean removed.
    pub(crate) dsnu: f64,
    /// DSNU as EMVA 1288 (release 4) computes it: from the fixed pattern
    /// high-pass filtered ([`highpass_variance`]), outliers (hot pixels)
    /// excluded, DN.
    pub(crate) dsnu_highpass: f64,
    pub(crate) frames: usize,
    /// PPCC of sampled pixels' temporal samples vs a Gaussian (paper Fig. 2),
    /// and of all those samples pooled without per-pixel centring/scaling.
    pub(crate) ppcc_pixels: Vec<f64>,
    pub(crate) ppcc_pooled: f64,
}

/// The fixed pattern (the pixel's constant offset, section 3.2.2, not numbered in the paper): the
/// per-pixel temporal mean of the bias frames minus the black level of its
/// plane, in DN. `mean` is `(4, h, w)` including black.
pub(crate) fn fixed_pattern(mean: &Array3<f64>, black: [f32; 4]) -> Array3<f32> {
    let mut out = Array3::<f32>::zeros(mean.raw_dim());
    for (p, mut plane) in out.outer_iter_mut().enumerate() {
        let m = mean.index_axis(ndarray::Axis(0), p);
        Zip::from(&mut plane)
            .and(&m)
            .for_each(|f, &x| *f = (x - black[p] as f64) as f32);
    }
    out
}

/// The spatial variance of a packed map's fine structure, as EMVA 1288
/// (release 4) measures non-uniformity: each plane minus its 5 x 5 box mean
/// (interior pixels, where the box fits), which removes shading such as a
/// flat's vignetting; values further than 5 robust standard deviations
/// (1.4826 MAD) from the median left out, which removes hot pixels and
/// other outliers; the variance times 25/24, the factor by which the
/// filter shrinks white noise's variance (1 - 2/25 + 1/25). DN^2 (or the
/// map's unit squared).
pub(crate) fn highpass_variance(map: &Array3<f32>) -> f64 {
    let (planes, h, w) = map.dim();
    let mut hp = Vec::new();
    for p in 0..planes {
        let a = map.index_axis(ndarray::Axis(0), p);
        for i in 2..h.saturating_sub(2) {
            for j in 2..w.saturating_sub(2) {
                let mut box_sum = 0.0f64;
                for di in 0..5 {
                    for dj in 0..5 {
                        box_sum += a[[i + di - 2, j + dj - 2]] as f64;
                    }
                }
                let v = a[[i, j]] as f64 - box_sum / 25.0;
                if v.is_finite() {
                    hp.push(v);
                }
            }
        }
    }
    if hp.len() < 2 {
        return f64::NAN;
    }
    let (med, sd) = median_and_robust_sd(&mut hp.clone());
    let kept: Vec<f64> = hp
        .into_iter()
        .filter(|v| (v - med).abs() <= 5.0 * sd)
        .collect();
    let n = kept.len() as f64;
    let m = kept.iter().sum::<f64>() / n;
    kept.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0).max(1.0) * 25.0 / 24.0
}

/// The source-follower (read) noise sigma_r of N_r per pixel (section
/// 3.2.2, not numbered in the paper): sqrt(Var(bias) - sigma_H^2), the per-pixel temporal variance
/// of the bias frames with the row-noise variance removed (and the
/// whole-frame offset drift's, which moves every pixel alike): `shared` is
/// their sum, DN^2; clamped at 0; in DN.
pub(crate) fn read_sigma(var: &Array3<f64>, shared: f64) -> Array3<f32> {
    var.mapv(|v| (v - shared).max(0.0).sqrt() as f32)
}

/// The median over pixels of the source-follower sigma, DN, from each
/// pixel's unbiased temporal variance over `frames` bias frames (`var`,
/// row noise and offset drift included) with `shared` (their variance,
/// DN^2) removed: the median of sqrt(var) corrected for the sampling error
/// of `frames` frames ([`crate::sample_sd::median_sigma`]), then the shared
/// variance taken out of its square (a median passes through the monotone
/// sqrt(v - shared)). The median of the per-pixel map instead would be
/// biased low: 2.8 % with 16 frames, more with fewer.
pub(crate) fn read_sigma_median(var: &Array3<f64>, shared: f64, frames: usize) -> f64 {
    match crate::sample_sd::median_sigma(var.iter().copied(), frames) {
        Some(total) => (total * total - shared).max(0.0).sqrt(),
        None => median_finite(&read_sigma(var, shared)),
    }
}

/// EMVA 1288's temporal dark noise sigma_y.dark, DN: the square root of the
/// mean over frame pairs of half the spatial variance of their difference
/// ([`crate::stack::pair_variance`], each pair's mean difference removed,
/// so whole-frame offset drift is not in it). Unbiased in the variance at
/// any number of frames; row noise and quantisation are in it, as in the
/// standard's. NaN without a pair.
pub(crate) fn dark_noise_sigma(pair_vars: &[f64]) -> f64 {
    if pair_vars.is_empty() {
        return f64::NAN;
    }
    (pair_vars.iter().sum::<f64>() / pair_vars.len() as f64)
        .max(0.0)
        .sqrt()
}

/// Bias-frame estimates: fixed pattern (`fixed_pattern`), read sigma
/// (`read_sigma`, and its median `read_sigma_median`), temporal dark noise
/// (`dark_noise_sigma`), row noise and frame offset drift
/// (`PixelStats::row_and_frame_variance`), DSNU, PPCC.
pub fn estimate_bias(stack: &Stack, black: [f32; 4]) -> Result<BiasEstimate> {
    let g = stack.groups.first().ok_or_else(|| CalibError::EmptyStack {
        stack: "bias".into(),
    })?;
    let (mean, var) = (g.stats.mean(), g.stats.var());
    let (row_var, frame_var) = g.stats.row_and_frame_variance();
    let fixed_pattern = fixed_pattern(&mean, black);
    let sigma_read = read_sigma(&var, row_var + frame_var);
    let read_sigma_median = read_sigma_median(&var, row_var + frame_var, g.files.len());
    let n = g.files.len() as f64;
    let fp_mean = fixed_pattern.iter().map(|&v| v as f64).sum::<f64>() / fixed_pattern.len() as f64;
    let fp_var = fixed_pattern
        .iter()
        .map(|&v| (v as f64 - fp_mean).powi(2))
        .sum::<f64>()
        / fixed_pattern.len() as f64;
    let mean_var = var.iter().sum::<f64>() / var.len() as f64;
    let dsnu = (fp_var - mean_var / n).max(0.0).sqrt();
    // The temporal noise left in a mean of n frames is white, so the
    // high-pass keeps all of it (after its correction factor).
    let dsnu_highpass = (highpass_variance(&fixed_pattern) - mean_var / n)
        .max(0.0)
        .sqrt();
    let ppcc_pixels: Vec<f64> = stack
        .tap
        .iter()
        .map(|s| ppcc(&s.iter().map(|&v| v as f64).collect::<Vec<_>>()))
        .filter(|v| v.is_finite())
        .collect();
    let pooled: Vec<f64> = stack.tap.iter().flatten().map(|&v| v as f64).collect();
    Ok(BiasEstimate {
        fixed_pattern,
        mean,
        var,
        sigma_read,
        read_sigma_median,
        dark_noise_sigma: dark_noise_sigma(&g.pair_vars),
        row_sigma: row_var.sqrt(),
        frame_offset_sigma: frame_var.sqrt(),
        dsnu,
        dsnu_highpass,
        frames: g.files.len(),
        ppcc_pixels,
        ppcc_pooled: ppcc(&pooled),
    })
}

/// How the system gain K was estimated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum GainMethod {
    /// Photon transfer: the slope of temporal variance over mean signal
    /// across flat levels.
    #[serde(rename = "ptc")]
    PhotonTransfer,
    /// Eq. 3.15 at the brightest level: temporal variance / mean signal
    /// (one level, or a failed transfer fit).
    #[serde(rename = "var/mean")]
    VarOverMean,
}

impl std::fmt::Display for GainMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            GainMethod::PhotonTransfer => "ptc",
            GainMethod::VarOverMean => "var/mean",
        })
    }
}

/// One flat level of the photon-transfer curve.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct PtcLevel {
    pub(crate) exposure_s: f64,
    /// Spatial mean of (flat mean - bias mean), DN.
    pub mean_dn: f64,
    /// The shot-noise variance, DN^2: the frame pairs' temporal variance
    /// (`crate::stack::pair_variance`, light drift removed) minus the bias
    /// frames' temporal variance.
    pub var_dn2: f64,
    /// The same from every pixel's temporal variance over the whole level
    /// minus the bias's, DN^2: what the light's drift between frames adds
    /// to the noise is in it (the estimate before EMVA's pair method).
    pub var_dn2_stack: f64,
    /// Relative standard deviation of the frames' mean signal: the light's
    /// drift over the level's frames.
    pub drift: f64,
    pub(crate) frames: usize,
}

/// From flat fields (several brightness levels): the system gain K, the
/// photon-transfer curve and per-pixel response.
#[derive(Clone, Debug)]
pub struct GainEstimate {
    /// Global system gain, DN per electron.
    pub(crate) k: f64,
    /// "ptc" (regression over levels) or "var/mean" (eq. 3.15, one level).
    pub(crate) method: GainMethod,
    /// Eq. 3.15 per pixel at the brightest level: (var_flat - var_bias) /
    /// (mean_flat - mean_bias); 0 where the pixel does not respond.
    pub(crate) k_map: Array3<f32>,
    /// Eq. 3.15 globally at the brightest level.
    pub(crate) k_var_mean: f64,
    /// K the same way (`method`) from the per-pixel temporal variance over
    /// each level's stack ([`PtcLevel::var_dn2_stack`]), the light's drift
    /// included: how far a drifting lamp would have moved it.
    pub k_without_pairs: f64,
    /// What the estimate could not check, for the output and the report
    /// (one flat level: no linearity check).
    pub warnings: Vec<String>,
    /// Per-pixel signal at the brightest level (flat mean - bias mean), DN.
    pub(crate) response: Array3<f32>,
    /// The photon-transfer curve's points, one per flat level, by exposure.
    pub levels: Vec<PtcLevel>,
    /// var = slope mean + intercept over the levels, when there are two or more.
    pub ptc_fit: Option<(f64, f64)>,
    /// PRNU: spatial sd of the per-pixel response at the brightest level,
    /// relative to its mean, temporal noise removed.
    pub(crate) prnu: f64,
    /// PRNU as EMVA 1288 (release 4) computes it: the response high-pass
    /// filtered, outliers excluded ([`highpass_variance`]): the flat's
    /// shading (vignetting, an uneven lamp) is not the sensor's.
    pub(crate) prnu_highpass: f64,
    /// The flat levels that clipped (left out of K), by exposure.
    pub saturated: Vec<PtcLevel>,
    /// EMVA 1288's saturation capacity, DN above bias: the mean signal of
    /// the level of largest temporal variance among all levels, when some
    /// level clipped (`saturation_dn`).
    pub saturation_dn: Option<f64>,
    /// EMVA 1288's linearity error, a fraction (`linearity_error`).
    pub linearity_error: Option<f64>,
    /// Standard error of K, DN/e- (statistical: from the photon-transfer
    /// fit's residuals with three levels or more, else from the pairs'
    /// sampling error).
    pub k_sigma: f64,
}

/// The system gain from one flat level, eq. 3.15: K = Var(D) / E(D) with
/// the bias removed from both (`var` = flat variance - bias variance, DN^2;
/// `mean` = flat mean - bias mean, DN), in DN per electron. Used per pixel
/// (the gain map) and globally (the level's spatial means).
pub(crate) fn gain_var_mean(var: f64, mean: f64) -> f64 {
    var / mean
}

/// Photon transfer: the least-squares line var = slope mean + intercept
/// through the flat levels' (mean, shot variance) points; its slope is K,
/// the robust form of eq. 3.15 over several light levels. `None` with fewer
/// than two levels or no spread in their means.
pub(crate) fn photon_transfer(levels: &[PtcLevel]) -> Option<(f64, f64)> {
    if levels.len() >= 2 {
        let n = levels.len() as f64;
        let mx = levels.iter().map(|l| l.mean_dn).sum::<f64>() / n;
        let my = levels.iter().map(|l| l.var_dn2).sum::<f64>() / n;
        let sxx: f64 = levels.iter().map(|l| (l.mean_dn - mx).powi(2)).sum();
        let sxy: f64 = levels
            .iter()
            .map(|l| (l.mean_dn - mx) * (l.var_dn2 - my))
            .sum();
        if sxx > 0.0 {
            let slope = sxy / sxx;
            Some((slope, my - slope * mx))
        } else {
            None
        }
    } else {
        None
    }
}

/// The statistical standard error of K (DN/e-) from `levels` (with
/// `pairs[i]` frame pairs each over `pixels` pixels): with three levels or
/// more, the photon-transfer slope's standard error from its residuals;
/// with fewer, propagated from each level's variance estimate, whose
/// relative standard error is sqrt(2 / (pairs x pixels)) (a variance over
/// that many independent differences).
pub(crate) fn gain_sigma(levels: &[PtcLevel], pairs: &[usize], pixels: usize, k: f64) -> f64 {
    let rel = |i: usize| (2.0 / (pairs[i].max(1) * pixels.max(1)) as f64).sqrt();
    match levels.len() {
        0 => f64::NAN,
        1 => k * rel(0),
        2 => {
            let dm = levels[1].mean_dn - levels[0].mean_dn;
            let sv = (levels[0].var_dn2 * rel(0)).hypot(levels[1].var_dn2 * rel(1));
            sv / dm.abs()
        }
        n => {
            let nf = n as f64;
            let mx = levels.iter().map(|l| l.mean_dn).sum::<f64>() / nf;
            let sxx: f64 = levels.iter().map(|l| (l.mean_dn - mx).powi(2)).sum();
            match photon_transfer(levels) {
                Some((slope, icpt)) if sxx > 0.0 => {
                    let ss: f64 = levels
                        .iter()
                        .map(|l| (l.var_dn2 - slope * l.mean_dn - icpt).powi(2))
                        .sum();
                    (ss / (nf - 2.0) / sxx).sqrt()
                }
                _ => f64::NAN,
            }
        }
    }
}

/// EMVA 1288's saturation point: the mean signal (DN above bias) of the
/// level whose temporal variance is largest, among the unclipped `levels`
/// and the `saturated` ones: past it the clipping eats the variance. `None`
/// when no level clipped (the flats never reached saturation, so the
/// largest variance is only the brightest level's).
pub(crate) fn saturation_dn(levels: &[PtcLevel], saturated: &[PtcLevel]) -> Option<f64> {
    if saturated.is_empty() {
        return None;
    }
    levels
        .iter()
        .chain(saturated)
        .max_by(|a, b| a.var_dn2.total_cmp(&b.var_dn2))
        .map(|l| l.mean_dn)
}

/// EMVA 1288's linearity error: the line mean = a t + b fitted by least
/// squares to the levels whose mean signal lies between 5 % and 95 % of
/// `full` (the saturation point, or the range to white), exposure time t
/// standing for the irradiation; the error is half the spread of the
/// relative deviations (mean - line) / line, as a fraction. `None` with
/// fewer than three such levels (two always lie on their line).
pub(crate) fn linearity_error(levels: &[PtcLevel], full: f64) -> Option<f64> {
    let pts: Vec<(f64, f64)> = levels
        .iter()
        .filter(|l| l.mean_dn >= 0.05 * full && l.mean_dn <= 0.95 * full)
        .map(|l| (l.exposure_s, l.mean_dn))
        .collect();
    if pts.len() < 3 {
        return None;
    }
    let n = pts.len() as f64;
    let mt = pts.iter().map(|p| p.0).sum::<f64>() / n;
    let mm = pts.iter().map(|p| p.1).sum::<f64>() / n;
    let stt: f64 = pts.iter().map(|p| (p.0 - mt).powi(2)).sum();
    if stt <= 0.0 {
        return None;
    }
    let a = pts.iter().map(|p| (p.0 - mt) * (p.1 - mm)).sum::<f64>() / stt;
    let b = mm - a * mt;
    let dev: Vec<f64> = pts
        .iter()
        .map(|p| (p.1 - (a * p.0 + b)) / (a * p.0 + b))
        .collect();
    let (lo, hi) = dev
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &d| {
            (l.min(d), h.max(d))
        });
    Some((hi - lo) / 2.0)
}

/// The largest share of a flat level's pixels that may touch the white
/// level: hot pixels and a few bright defects do, a clipped flat does not.
const MAX_CLIPPED: f64 = 0.01;

/// Share of pixels whose mean plus three temporal sigma reaches `white` (DN):
/// those frames clip part of the distribution, so their variance, and the
/// gain from it, is too small.
fn clipped_fraction(mean: &Array3<f64>, var: &Array3<f64>, white: u32) -> f64 {
    let white = white as f64;
    let n = Zip::from(mean).and(var).fold(0usize, |acc, &m, &v| {
        acc + (m + 3.0 * v.max(0.0).sqrt() >= white) as usize
    });
    n as f64 / mean.len().max(1) as f64
}

/// Flat-field estimates: K by photon transfer ([`photon_transfer`]) or
/// eq. 3.15 ([`gain_var_mean`]), the per-pixel gain map, PRNU.
pub(crate) fn estimate_gain(flat: &Stack, bias: &BiasEstimate) -> Result<GainEstimate> {
    let bias_var = bias.var.mean().unwrap_or(0.0);
    let FlatLevels {
        levels,
        saturated,
        bright: (bm, bv, bi),
    } = flat_levels(flat, bias, bias_var)?;
    let bright_level = levels[bi];
    let k_map = gain_map(&bm, &bv, bias, bright_level.drift.powi(2));
    let k_var_mean = gain_var_mean(bright_level.var_dn2, bright_level.mean_dn);
    // PRNU from the spread of the per-pixel signal at the brightest level.
    let response = Zip::from(&bm)
        .and(&bias.mean)
        .map_collect(|a, b| (a - b) as f32);
    let (prnu, prnu_highpass) = prnu_of(&response, &bright_level, bias, bias_var);

    let ptc_fit = photon_transfer(&levels);
    let (k, method) = match ptc_fit {
        Some((slope, _)) if slope > 0.0 => (slope, GainMethod::PhotonTransfer),
        _ => (k_var_mean, GainMethod::VarOverMean),
    };
    let stacked: Vec<PtcLevel> = levels
        .iter()
        .map(|l| PtcLevel {
            var_dn2: l.var_dn2_stack,
            ..*l
        })
        .collect();
    let k_without_pairs = match (method, photon_transfer(&stacked)) {
        (GainMethod::PhotonTransfer, Some((slope, _))) => slope,
        _ => gain_var_mean(bright_level.var_dn2_stack, bright_level.mean_dn),
    };
    let saturation = saturation_dn(&levels, &saturated);
    let range = flat.key.white as f64 - bias.mean.mean().unwrap_or(0.0);
    let linearity = linearity_error(&levels, saturation.unwrap_or(range));
    let pairs: Vec<usize> = flat
        .groups
        .iter()
        .filter(|g| levels.iter().any(|l| l.exposure_s == g.exposure_s))
        .map(|g| g.pair_vars.len())
        .collect();
    let k_sigma = gain_sigma(&levels, &pairs, bm.len(), k);
    let mut warnings = Vec::new();
    if levels.len() < 2 {
        warnings.push(format!(
            "one flat level ({} s): K is eq. 3.15 at that level alone, with no photon-transfer fit to check the sensor's linearity; give flats at two or more exposure times",
            bright_level.exposure_s
        ));
    }
    if !(k.is_finite() && k > 0.0) {
        return Err(CalibError::BadGain { k });
    }
    Ok(GainEstimate {
        k,
        method,
        k_map,
        k_var_mean,
        k_without_pairs,
        warnings,
        prnu_highpass,
        k_sigma,
        saturated,
        saturation_dn: saturation,
        linearity_error: linearity,
        response,
        levels,
        ptc_fit,
        prnu,
    })
}

/// The flat stack's levels: those usable for the gain, those too clipped
/// for it (where the saturation capacity shows), and the brightest usable
/// one's per-pixel mean and variance with its index.
struct FlatLevels {
    levels: Vec<PtcLevel>,
    saturated: Vec<PtcLevel>,
    bright: (Array3<f64>, Array3<f64>, usize),
}

fn flat_levels(flat: &Stack, bias: &BiasEstimate, bias_var: f64) -> Result<FlatLevels> {
    let mut levels: Vec<PtcLevel> = Vec::new();
    // Mean and variance of the brightest level so far: each is a full-frame
    // f64 copy, so they are kept from the loop rather than recomputed.
    let mut bright: Option<(Array3<f64>, Array3<f64>, usize)> = None;
    let mut saturated: Vec<PtcLevel> = Vec::new();
    let mut clipped_note = None;
    for g in &flat.groups {
        let (m, v) = (g.stats.mean(), g.stats.var());
        let level = level_of(g, &m, &v, bias, bias_var)?;
        let clipped = clipped_fraction(&m, &v, flat.key.white);
        if clipped > MAX_CLIPPED {
            // A clipped level has too little variance for the gain, but it
            // is where the saturation capacity shows (EMVA 1288 runs its
            // flats up to saturation).
            saturated.push(level);
            clipped_note = Some((g.exposure_s, clipped));
            continue;
        }
        if bright
            .as_ref()
            .is_none_or(|(_, _, i)| level.mean_dn > levels[*i].mean_dn)
        {
            bright = Some((m, v, levels.len()));
        }
        levels.push(level);
    }
    let bright = match (bright, clipped_note) {
        (Some(b), _) => b,
        (None, Some((t, clipped))) => {
            return Err(CalibError::SaturatedFlats {
                exposure_s: t,
                clipped,
                white: flat.key.white,
            })
        }
        (None, None) => {
            return Err(CalibError::EmptyStack {
                stack: "flat".into(),
            })
        }
    };
    Ok(FlatLevels {
        levels,
        saturated,
        bright,
    })
}

/// One flat level's point of the photon-transfer curve: mean signal over
/// the bias, the temporal variance from frame pairs (and from the stack),
/// and the light's drift between frames.
fn level_of(
    g: &Group,
    m: &Array3<f64>,
    v: &Array3<f64>,
    bias: &BiasEstimate,
    bias_var: f64,
) -> Result<PtcLevel> {
    let n = m.len() as f64;
    let mean_dn = Zip::from(m)
        .and(&bias.mean)
        .fold(0.0, |acc, a, b| acc + (a - b))
        / n;
    let var_dn2_stack = Zip::from(v)
        .and(&bias.var)
        .fold(0.0, |acc, a, b| acc + (a - b))
        / n;
    if g.pair_vars.is_empty() {
        return Err(CalibError::NoFlatPair {
            exposure_s: g.exposure_s,
        });
    }
    let var_dn2 = g.pair_vars.iter().sum::<f64>() / g.pair_vars.len() as f64 - bias_var;
    let black = bias.mean.mean().unwrap_or(0.0);
    let signal: Vec<f64> = g.frame_means.iter().map(|m| m - black).collect();
    let sm = signal.iter().sum::<f64>() / signal.len() as f64;
    let drift = (signal.iter().map(|s| (s - sm).powi(2)).sum::<f64>()
        / (signal.len() as f64 - 1.0).max(1.0))
    .sqrt()
        / sm.abs().max(f64::MIN_POSITIVE);
    if mean_dn <= 0.0 {
        return Err(CalibError::FlatNotBrighter {
            exposure_s: g.exposure_s,
            mean_dn,
        });
    }
    Ok(PtcLevel {
        exposure_s: g.exposure_s,
        mean_dn,
        var_dn2,
        var_dn2_stack,
        drift,
        frames: g.files.len(),
    })
}

/// Each pixel's gain by eq. 3.15 at the brightest level (`bm`, `bv`), its
/// variance freed of the light's drift: a change of the light by a factor
/// (1 + e_f) moves pixel x by s(x) e_f, adding s(x)^2 var(e) to its
/// temporal variance, where s is its signal; the level's drift (the
/// frames' relative spread of mean signal) gives var(e) = `drift2`.
fn gain_map(bm: &Array3<f64>, bv: &Array3<f64>, bias: &BiasEstimate, drift2: f64) -> Array3<f32> {
    let mut k_map = Array3::<f32>::zeros(bm.raw_dim());
    Zip::from(&mut k_map)
        .and(bm)
        .and(bv)
        .and(&bias.mean)
        .and(&bias.var)
        .for_each(|k, &fm, &fv, &m0, &v0| {
            let s = fm - m0;
            // A pixel that does not respond (a dead one, flagged so) has no
            // gain to measure: 0, not NaN, so every map stays finite.
            *k = if s > 0.0 {
                gain_var_mean(fv - v0 - s * s * drift2, s) as f32
            } else {
                0.0
            };
        });
    k_map
}

/// PRNU (and its EMVA 1288 high-pass form) from the spread of the
/// per-pixel response at the brightest level, less the temporal noise the
/// means still hold (the response is flat mean minus bias mean: the fixed
/// pattern cancels, the temporal noise of both means is left in it).
fn prnu_of(
    response: &Array3<f32>,
    bright: &PtcLevel,
    bias: &BiasEstimate,
    bias_var: f64,
) -> (f64, f64) {
    let sig: Vec<f64> = response.iter().map(|&v| v as f64).collect();
    let sm = sig.iter().sum::<f64>() / sig.len() as f64;
    let sv = sig.iter().map(|s| (s - sm).powi(2)).sum::<f64>() / sig.len() as f64;
    let temporal =
        (bright.var_dn2 + bias_var) / bright.frames as f64 + bias_var / bias.frames as f64;
    let prnu = (sv - temporal).max(0.0).sqrt() / sm;
    let prnu_highpass = (highpass_variance(response) - temporal).max(0.0).sqrt() / sm;
    (prnu, prnu_highpass)
}

/// From dark frames (two or more exposure times, any number of frames at
/// each): the dark-current law and per-pixel dark rate.
#[derive(Clone, Debug)]
pub struct DarkEstimate {
    pub(crate) exposures: Vec<f64>,
    /// The law with the better fit of the pixel-averaged dark signal
    /// ([`choose_dark_law`]).
    pub(crate) law: DarkLaw,
    /// Whether the law has an offset term c (y = a g(t) + c).
    pub offset: bool,
    /// R^2 of the pixel-averaged dark signal under a sqrt(t) (+ c when
    /// `offset`).
    pub r2_sqrt_global: f64,
    /// R^2 of the pixel-averaged dark signal under a t (+ c when `offset`).
    pub r2_linear_global: f64,
    /// Per-pixel R^2 of each law, in the chosen offset form (0 where the
    /// pixel's dark signal does not vary: nothing to explain, and the maps
    /// stay finite).
    pub(crate) r2_sqrt: Array3<f32>,
    pub(crate) r2_linear: Array3<f32>,
    /// Per-pixel dark rate in electrons per sqrt(s) or per s (chosen law),
    /// N_FP absorbed (mean dark DN = K rate g(t) + c).
    pub(crate) rate: Array3<f32>,
    /// Mean dark rate, electrons per unit of g(t) (sqrt(s) or s, after the chosen law).
    pub rate_mean: f64,
    /// Per-pixel offset c of the dark signal, DN, when `offset`.
    pub(crate) offset_dn: Option<Array3<f32>>,
    /// Mean offset c, DN (0 without an offset term).
    pub offset_mean_dn: f64,
}

/// One dark-current law fitted to a dark signal: y = a g(t) + c (c = 0
/// for the laws through the origin).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LawFit {
    /// Slope, DN per unit of g(t).
    pub a: f64,
    /// Offset, DN (0 through the origin).
    pub c: f64,
    /// Weighted sum of squared residuals.
    pub ss_res: f64,
    /// 1 - SS_res / SS_tot, SS_tot about the weighted mean of y (NaN when y
    /// does not vary).
    pub r2: f64,
}

/// The dark-current law fit: weighted least squares of y = a g (through the
/// origin, the paper's y = a sqrt(t) with g = sqrt(t), or y = a t), or with
/// `offset` of y = a g + c, and its R^2. `y` is the dark signal
/// ([`dark_signal`]) at the exposure times' g(t); the weights `w` are the
/// frames averaged at each exposure (a mean of n frames has 1/n of the
/// noise variance), so one frame per exposure is fine and simply weighs
/// less.
pub(crate) fn fit_dark_law(g: &[f64], y: &[f64], w: &[f64], offset: bool) -> LawFit {
    let sw: f64 = w.iter().sum();
    let wsum = |f: &dyn Fn(usize) -> f64| (0..y.len()).map(|i| w[i] * f(i)).sum::<f64>();
    let my = wsum(&|i| y[i]) / sw;
    let ss_tot = wsum(&|i| (y[i] - my).powi(2));
    let (a, c) = if offset {
        let mg = wsum(&|i| g[i]) / sw;
        let sgg = wsum(&|i| (g[i] - mg).powi(2));
        let sgy = wsum(&|i| (g[i] - mg) * (y[i] - my));
        if sgg > 0.0 {
            let a = sgy / sgg;
            (a, my - a * mg)
        } else {
            (0.0, my)
        }
    } else {
        let sgg = wsum(&|i| g[i] * g[i]);
        (
            if sgg > 0.0 {
                wsum(&|i| g[i] * y[i]) / sgg
            } else {
                0.0
            },
            0.0,
        )
    };
    let ss_res = wsum(&|i| (y[i] - a * g[i] - c).powi(2));
    LawFit {
        a,
        c,
        ss_res,
        r2: if ss_tot > 0.0 {
            1.0 - ss_res / ss_tot
        } else {
            f64::NAN
        },
    }
}

/// F(1, nu) at the 99th percentile (the square of Student's t at 0.995), for
/// the test of an offset term with nu = exposures - 2 degrees of freedom.
fn f_crit_99(nu: usize) -> f64 {
    // Student's t quantiles t(0.995, nu), nu = 1..=30, then 40, 60, 120.
    const T: [f64; 30] = [
        63.657, 9.925, 5.841, 4.604, 4.032, 3.707, 3.499, 3.355, 3.250, 3.169, 3.106, 3.055, 3.012,
        2.977, 2.947, 2.921, 2.898, 2.878, 2.861, 2.845, 2.831, 2.819, 2.807, 2.797, 2.787, 2.779,
        2.771, 2.763, 2.756, 2.750,
    ];
    let t = match nu {
        0 => f64::INFINITY,
        1..=30 => T[nu - 1],
        31..=40 => 2.704,
        41..=60 => 2.660,
        61..=120 => 2.617,
        _ => 2.576,
    };
    t * t
}

/// The dark-current law of a sensor, from its pixel-averaged dark signal `y`
/// at exposure times `t` (weights `w`, see [`fit_dark_law`]): for each of
/// g = sqrt(t) and g = t the offset c is kept when it improves the fit
/// significantly (F-test at 1 %: F = (SS_0 - SS_c) / (SS_c / (n - 2)) above
/// the 99th percentile of F(1, n - 2); it needs three exposures or more),
/// then the g whose kept fit has the smaller residual variance SS / (n - p)
/// (p parameters) wins. The paper's sqrt(t) is a CMOS finding; CCDs are
/// linear, often with an offset. Returns the law, whether it has the offset,
/// and the sqrt(t) and t fits in that offset form.
pub(crate) fn choose_dark_law(t: &[f64], y: &[f64], w: &[f64]) -> (DarkLaw, bool, LawFit, LawFit) {
    let n = t.len();
    let gs: Vec<f64> = t.iter().map(|v| v.sqrt()).collect();
    let candidates = [(DarkLaw::Sqrt, &gs[..]), (DarkLaw::Linear, t)];
    let kept: Vec<(DarkLaw, bool, f64)> = candidates
        .iter()
        .map(|&(law, g)| {
            let origin = fit_dark_law(g, y, w, false);
            if n < 3 {
                return (law, false, origin.ss_res / (n - 1).max(1) as f64);
            }
            let with = fit_dark_law(g, y, w, true);
            let f = (origin.ss_res - with.ss_res)
                / (with.ss_res / (n - 2) as f64).max(f64::MIN_POSITIVE);
            if f > f_crit_99(n - 2) {
                (law, true, with.ss_res / (n - 2) as f64)
            } else {
                (law, false, origin.ss_res / (n - 1) as f64)
            }
        })
        .collect();
    let best = if kept[1].2 < kept[0].2 {
        kept[1]
    } else {
        kept[0]
    };
    let (law, offset) = (best.0, best.1);
    (
        law,
        offset,
        fit_dark_law(&gs, y, w, offset),
        fit_dark_law(t, y, w, offset),
    )
}

/// The dark signal of every pixel at one exposure time (eq. 3.16):
/// the dark frames' temporal mean minus the bias frames' (fixed pattern and
/// black cancel), DN, flattened in packed order.
pub(crate) fn dark_signal(dark_mean: &Array3<f64>, bias_mean: &Array3<f64>) -> Vec<f64> {
    Zip::from(dark_mean)
        .and(bias_mean)
        .map_collect(|a, b| a - b)
        .into_iter()
        .collect()
}

/// The pixel's dark-current rate in electrons per unit of g(t) (sqrt(s) or
/// s) from its fitted dark-signal slope `a` (DN per unit of g(t)) and the
/// gain K (eq. 3.17, E(N) = K2 E(N_RS) with K2 = 1 + N_FP): the
/// dark signal's mean is K rate g(t) with the pixel's K2 absorbed into its
/// rate, so rate = a / K (clamped at 0).
pub(crate) fn dark_rate(a: f64, k: f64) -> f32 {
    (a / k).max(0.0) as f32
}

/// Dark-frame estimates: dark signal ([`dark_signal`]) per exposure, the law
/// ([`choose_dark_law`]) on the pixel-averaged signal, per-pixel rates
/// ([`dark_rate`]), offsets and R^2 maps ([`fit_dark_law`]).
pub(crate) fn estimate_dark(dark: &Stack, bias: &BiasEstimate, k: f64) -> Result<DarkEstimate> {
    let exposures: Vec<f64> = dark.groups.iter().map(|g| g.exposure_s).collect();
    if exposures.len() < 2 {
        return Err(CalibError::TooFewExposures {
            stack: "dark".into(),
            exposure_s: exposures.first().copied().unwrap_or(0.0),
            needed: 2,
        });
    }
    let w: Vec<f64> = dark.groups.iter().map(|g| g.files.len() as f64).collect();
    // Per group, the dark signal of every pixel: mean minus the bias mean.
    let sig: Vec<Vec<f64>> = dark
        .groups
        .iter()
        .map(|g| dark_signal(&g.stats.mean(), &bias.mean))
        .collect();
    let gs = exposures.iter().map(|t| t.sqrt()).collect::<Vec<_>>();
    let gl = exposures.clone();
    let avg: Vec<f64> = sig
        .iter()
        .map(|s| s.iter().sum::<f64>() / s.len() as f64)
        .collect();
    let (law, offset, fs, fl) = choose_dark_law(&exposures, &avg, &w);
    let shape = bias.mean.raw_dim();
    let npx = sig[0].len();
    let mut r2_sqrt = vec![0f32; npx];
    let mut r2_linear = vec![0f32; npx];
    let mut rate = vec![0f32; npx];
    let mut c_map = vec![0f32; npx];
    let mut y = vec![0.0; exposures.len()];
    for x in 0..npx {
        for (t, s) in y.iter_mut().zip(&sig) {
            *t = s[x];
        }
        let a = fit_dark_law(&gs, &y, &w, offset);
        let b = fit_dark_law(&gl, &y, &w, offset);
        let finite = |r: f64| if r.is_finite() { r as f32 } else { 0.0 };
        r2_sqrt[x] = finite(a.r2);
        r2_linear[x] = finite(b.r2);
        let chosen = if law == DarkLaw::Sqrt { a } else { b };
        rate[x] = dark_rate(chosen.a, k);
        c_map[x] = chosen.c as f32;
    }
    let rate = Array3::from_shape_vec(shape, rate).expect("shape");
    let offset_mean_dn = if offset {
        c_map.iter().map(|&v| v as f64).sum::<f64>() / npx as f64
    } else {
        0.0
    };
    Ok(DarkEstimate {
        exposures,
        law,
        offset,
        r2_sqrt_global: fs.r2,
        r2_linear_global: fl.r2,
        r2_sqrt: Array3::from_shape_vec(shape, r2_sqrt).expect("shape"),
        r2_linear: Array3::from_shape_vec(shape, r2_linear).expect("shape"),
        rate_mean: rate.mean().unwrap_or(0.0) as f64,
        rate,
        offset_dn: offset.then(|| Array3::from_shape_vec(shape, c_map).expect("shape")),
        offset_mean_dn,
    })
}

/// Codes of the defect map.
pub mod defect {
    /// A good pixel.
    pub const GOOD: f32 = 0.0;
    /// Dark rate (or bias offset) far above the rest.
    pub const HOT: f32 = 1.0;
    /// Response to light below half the median.
    pub const DEAD: f32 = 2.0;
    /// Bias offset far below the rest.
    pub const COLD: f32 = 3.0;
    /// In a sensor column whose offset or response stands out from its
    /// neighbouring columns' (module `columns`).
    pub const COLUMN: f32 = 4.0;
}

/// Median and robust standard deviation (1.4826 MAD, floored at 1e-6) of
/// the finite values of a map.
fn robust_stats<'a>(values: impl IntoIterator<Item = &'a f32>) -> (f64, f64) {
    let mut v: Vec<f64> = values
        .into_iter()
        .filter(|x| x.is_finite())
        .map(|&x| x as f64)
        .collect();
    let (m, sd) = median_and_robust_sd(&mut v);
    (m, sd.max(1e-6))
}

/// Defect map ([`defect`] codes): hot (dark rate, or the bias offset
/// without darks, above median + 10 robust sd), cold (bias offset below
/// median - 10 robust sd), dead (mean response below half the median), and
/// the pixels of defective columns (physical sensor columns that stand out
/// from their neighbours in the bias offset or the response,
/// [`crate::columns::defective_columns`]; `offsets`: each packed plane's
/// place in the 2 x 2 cell) that are not flagged otherwise. Returns the map
/// and the number of defective sensor columns, each counted once.
pub(crate) fn defects(
    bias: &BiasEstimate,
    gain: Option<&GainEstimate>,
    dark: Option<&DarkEstimate>,
    offsets: [(usize, usize); 4],
) -> (Array3<f32>, usize) {
    let mut out = Array3::<f32>::zeros(bias.fixed_pattern.raw_dim());
    let hot_src = dark.map(|d| &d.rate).unwrap_or(&bias.fixed_pattern);
    let (m, sd) = robust_stats(hot_src);
    Zip::from(&mut out).and(hot_src).for_each(|o, &v| {
        if v as f64 > m + 10.0 * sd {
            *o = defect::HOT;
        }
    });
    let (mb, sdb) = robust_stats(&bias.fixed_pattern);
    Zip::from(&mut out)
        .and(&bias.fixed_pattern)
        .for_each(|o, &v| {
            if *o == defect::GOOD && (v as f64) < mb - 10.0 * sdb {
                *o = defect::COLD;
            }
        });
    // Dead: the mean response, not the per-pixel gain, which is too noisy
    // (its variance term has a relative error of sqrt(2/(F-1))).
    if let Some(g) = gain {
        let mr = median_finite(&g.response);
        Zip::from(&mut out).and(&g.response).for_each(|o, &v| {
            if (v as f64) < 0.5 * mr || !v.is_finite() {
                *o = defect::DEAD;
            }
        });
    }
    // Columns from the flats' response only: an offset column in the bias
    // (a column amplifier's pedestal) is removed by subtracting the master
    // bias or the fixed pattern, so replacing its pixels would only blur.
    let columns = match gain {
        Some(g) => mark_columns(&mut out, &g.response, offsets),
        None => 0,
    };
    (out, columns)
}

/// Mark in the packed defect map `out` the stretches of sensor columns
/// where `response` shows a column defect
/// ([`crate::columns::defective_column_rows`]); returns how many sensor
/// columns have one.
fn mark_columns(
    out: &mut Array3<f32>,
    response: &Array3<f32>,
    offsets: [(usize, usize); 4],
) -> usize {
    let (flags, columns) = crate::columns::defective_column_rows(response, offsets);
    let w = 2 * out.dim().2;
    for (p, &(dy, dx)) in offsets.iter().enumerate().take(out.dim().0) {
        for ((i, j), o) in out.index_axis_mut(ndarray::Axis(0), p).indexed_iter_mut() {
            if *o == defect::GOOD && flags[(2 * i + dy) * w + 2 * j + dx] {
                *o = defect::COLUMN;
            }
        }
    }
    columns.len()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn level(exposure_s: f64, mean_dn: f64, var_dn2: f64) -> PtcLevel {
        PtcLevel {
            exposure_s,
            mean_dn,
            var_dn2,
            var_dn2_stack: var_dn2,
            drift: 0.0,
            frames: 8,
        }
    }

    /// Three points, the middle one 3 % high: the line through them by
    /// hand is 100 t + 2, the deviations -1.961 %, +1.980 %, -0.662 %.
    #[test]
    fn linearity_error_by_hand() {
        let l = [
            level(1.0, 100.0, 1.0),
            level(2.0, 206.0, 1.0),
            level(3.0, 300.0, 1.0),
        ];
        let le = linearity_error(&l, 320.0).unwrap();
        let want = (4.0 / 202.0 + 2.0 / 102.0) / 2.0;
        assert!((le - want).abs() < 1e-12, "{le} vs {want}");
        // A level above 95 % of full is left out, and two are not enough.
        assert_eq!(linearity_error(&l, 300.0), None);
        // A straight line has none.
        let straight = [
            level(1.0, 100.0, 1.0),
            level(2.0, 200.0, 1.0),
            level(4.0, 400.0, 1.0),
        ];
        assert!(linearity_error(&straight, 1000.0).unwrap() < 1e-12);
    }

    #[test]
    fn saturation_is_the_level_of_largest_variance_once_flats_clip() {
        let unclipped = [level(1.0, 1000.0, 1500.0), level(2.0, 2000.0, 3000.0)];
        assert_eq!(saturation_dn(&unclipped, &[]), None);
        let clipped = [level(3.0, 2900.0, 2000.0), level(4.0, 3000.0, 10.0)];
        assert_eq!(saturation_dn(&unclipped, &clipped), Some(2000.0));
        let higher = [level(3.0, 2900.0, 3500.0)];
        assert_eq!(saturation_dn(&unclipped, &higher), Some(2900.0));
    }
}
