//! Poisson-Gaussian camera profiles from the noise descriptions other
//! tools write: the DNG NoiseProfile tag (`--profile dng:FILE.dng`).
//!
//! Those describe noise as a variance S x + O of the signal x normalised to
//! [0, 1] (black 0, white 1). In pgrf's DN terms, on a scale of
//! `range` = white - black DN, a signal of x range DN has shot variance
//! K x range and read variance sigma^2, so
//!
//! K = S range and sigma = sqrt(O) range.
//!
//! That is all such a description holds: no row noise, no fixed pattern,
//! no heavy-tailed read noise, one ISO. The profile made from it drives the
//! Poisson-Gaussian model (`--model pg`) exactly; ELD's and pgrf's models
//! run on it with those components at zero and a near-Gaussian read noise.

use crate::error::{NoiseError, Result};
use crate::profile::{CameraProfile, EldFits, IsoPoint, LogFit};
use std::path::Path;

/// Tukey lambda of a near-Gaussian read noise (0.14 matches the normal
/// distribution's shape most closely), for the models that draw one.
const GAUSSIAN_LAMBDA: f64 = 0.14;

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

/// A single-ISO Poisson-Gaussian profile of `noise`, named `name`, of the
/// camera `make` `model`; `source` says where the numbers came from.
pub fn poisson_gaussian(
    name: &str,
    make: &str,
    model: &str,
    noise: &PgNoise,
    source: String,
) -> Result<CameraProfile> {
    let &PgNoise {
        iso,
        s,
        o,
        range,
        black,
    } = noise;
    let bad = |reason: String| NoiseError::Profile {
        name: name.to_string(),
        reason,
    };
    if !(s.is_finite() && s > 0.0 && o.is_finite() && o >= 0.0) {
        return Err(bad(format!(
            "the noise pair (S {s}, O {o}) needs S > 0 and O >= 0, both finite"
        )));
    }
    let k = s * range;
    let sigma = o.sqrt() * range;
    let flat = |v: f64| LogFit {
        slope: 0.0,
        bias: v.max(1e-12).ln(),
        sigma: 0.0,
    };
    let p = CameraProfile {
        schema: 1,
        name: name.to_string(),
        make: make.to_string(),
        model: model.to_string(),
        source,
        units: "DN on the scale dn_range = white - black".into(),
        dn_range: range,
        black: Some(black),
        k_per_iso: None,
        k_min: k,
        k_max: k,
        eld: EldFits {
            tukey_shapes: vec![GAUSSIAN_LAMBDA],
            tukey_scale: flat(sigma),
            gauss_scale: flat(sigma),
            row_scale: flat(0.0),
            color_bias: Vec::new(),
        },
        per_iso: vec![IsoPoint {
            iso,
            k,
            tukey_lambda: GAUSSIAN_LAMBDA,
            sigma_tukey: sigma,
            sigma_gauss: sigma,
            sigma_row: 0.0,
            black_level_error: 0.0,
        }],
        dark_current: None,
    };
    p.checked().map_err(bad)
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
    let frame = pgrf_raw::decode_file(path, &Default::default()).map_err(|e| bad(e.to_string()))?;
    let bytes = std::fs::read(path).map_err(|e| bad(e.to_string()))?;
    let planes = if frame.mono { 1 } else { 3 };
    let pairs = pgrf_raw::container::noise_profile(&bytes, planes)
        .map_err(bad)?
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
