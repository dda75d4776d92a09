//! The noise models and the one sampling engine they share.
//!
//! The paper's composite model for one pixel (x, y), in DN above black:
//!
//! ```text
//! D = K (I + N_s) + N_RS (1 + N_FP) + N_H + N_r + N_q
//! ```
//!
//! with one function per term, used by [`NoiseModel::sample`] (synthetic
//! pairs) and by the virtual sensor ([`crate::sensor`]) alike:
//!
//! | term | meaning | letter | function |
//! |---|---|---|---|
//! | K (I + N_s) | photon shot: K times Poisson(I electrons) | P | [`photon_shot`] |
//! | N_RS (1 + N_FP) | dark-current shot K Poisson(d(t)), times the pixel's fixed-pattern factor | A, F | [`dark_shot`] |
//! | b(x, y) | fixed-pattern offset (calibrated bias mean) / ELD's colour bias | F | added in [`NoiseModel::sample`] |
//! | N_r | source-follower (read) noise sigma_r(x, y) N(0, 1) or Tukey | G | [`read_noise`] (a row's Tukey quantiles at once in [`NoiseModel::sample`]: [`tukey::quantiles_in_place`]) |
//! | N_H | row noise, one N(0, sigma_H) per sensor row | H | [`row_noise`] |
//! | N_q | quantisation, U(-q/2, q/2) | Q | [`quantisation`] |
//!
//! - P-G (Foi): P + Gaussian G.
//! - ELD: P + Tukey-lambda (or Gaussian) G + H + Q + per-channel colour bias.
//! - PGRF: everything, with per-pixel maps; "noD" replaces them by their
//!   means ([`PixelMaps::global`]).
//!
//! A component that is switched off contributes nothing; with P off the
//! signal passes through noiselessly. The ADC's range is respected: results
//! are clipped at white, and at 0 DN when the profile knows its black level.

use crate::components::Components;
use crate::error::{NoiseError, Result};
use crate::maps::{Map, PixelMaps};
use crate::params::CaptureParams;
use crate::poisson::poisson;
use crate::profile::{CameraProfile, DarkLaw};
use crate::tukey;
use ndarray::{Array3, ArrayView3};
use pgrf_core::parse::ParseError;
use pgrf_core::seed::{open01, stream, Domain};
use rand::Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// Read-noise distribution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ReadDist {
    /// N(0, sigma_read^2).
    Gaussian,
    /// Tukey-lambda with this shape; `sigma_read` is its scale.
    Tukey {
        /// Shape parameter lambda (0 is the logistic distribution).
        lambda: f32,
    },
}

/// Which model a user asked for (`pg`, `eld` or `pgrf` in flags, files and
/// records).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModelKind {
    /// Foi's Poisson-Gaussian model: shot noise plus Gaussian read noise.
    #[serde(rename = "pg", alias = "poissongaussian")]
    PoissonGaussian,
    /// ELD's model: shot, Tukey-lambda or Gaussian read, row, quantisation.
    Eld,
    /// The paper's composite model with per-pixel calibration maps
    /// (pgrf's default).
    #[default]
    Pgrf,
}

impl ModelKind {
    /// The terms this model draws when `asked` are asked for: the
    /// Poisson-Gaussian and ELD models have theirs ([`Components::PG`],
    /// [`Components::ELD`]); the PGRF model draws those asked.
    pub fn components(self, asked: Components) -> Components {
        match self {
            ModelKind::PoissonGaussian => Components::PG,
            ModelKind::Eld => Components::ELD,
            ModelKind::Pgrf => asked,
        }
    }

    /// The name in flags, files and records.
    pub(crate) fn name(self) -> &'static str {
        match self {
            ModelKind::PoissonGaussian => "pg",
            ModelKind::Eld => "eld",
            ModelKind::Pgrf => "pgrf",
        }
    }
}

impl std::fmt::Display for ModelKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for ModelKind {
    type Err = ParseError;
    fn from_str(s: &str) -> std::result::Result<Self, ParseError> {
        match s.to_ascii_lowercase().as_str() {
            "pg" => Ok(ModelKind::PoissonGaussian),
            "eld" => Ok(ModelKind::Eld),
            "pgrf" => Ok(ModelKind::Pgrf),
            o => Err(ParseError::unknown_name(
                s,
                format!("unknown noise model '{o}' (pg, eld or pgrf)"),
            )),
        }
    }
}

/// A noise model resolved for one capture: the parameters of
/// D = K (I + N_s) + N_RS (1 + N_FP) + N_H + N_r + N_q (plus the
/// fixed-pattern offset b(x, y)).
#[derive(Clone, Debug)]
pub struct NoiseModel {
    /// K, the system gain, DN per electron.
    pub k: f32,
    /// Distribution of N_r (Gaussian, or ELD's Tukey-lambda).
    pub read: ReadDist,
    /// Per-pixel (or per-plane, or scalar) maps: offset b(x, y), N_r's sigma,
    /// the dark rate of N_RS with its time law, and N_FP.
    pub maps: PixelMaps,
    /// sigma_H, the standard deviation of N_H, DN.
    pub row_sigma: f32,
    /// Quantisation step q of N_q, DN.
    pub quant_step: f32,
    /// Which terms are drawn (the paper's ablation letters).
    pub components: Components,
    /// white - black in DN: maps normalised images to the model's DN.
    pub dn_range: f32,
    /// Black level in DN, when known: values are clipped at 0 DN.
    pub black: Option<f32>,
    /// The sensor's own residual noise frames, drawn instead of the
    /// parametric read, row and quantisation noise (components G, H and Q
    /// together, when any of them is asked for).
    pub bank: Option<std::sync::Arc<crate::bank::NoiseBank>>,
}

/// One capture's conditions.
#[derive(Clone, Copy, Debug)]
pub struct Capture {
    /// Exposure ratio: the clean image is divided by it, the noisy result multiplied back.
    pub ratio: f32,
    /// Exposure time of the noisy capture, seconds (drives the dark current).
    pub exposure_s: f32,
    /// Sensor-row parity of each packed plane (R, G1, B, G2): row noise is
    /// shared by the planes read out on the same sensor row. From the CFA.
    pub plane_rows: [usize; 4],
    /// Seed of every draw; the output does not depend on the thread count.
    pub seed: u64,
}

/// Photon shot noise, the paper's K (I + N_s): `electrons` I of signal
/// (I + N_s ~ Poisson(I)) converted at `k` DN per electron (K, or the
/// virtual sensor's per-pixel gain). One Poisson draw from `rng`.
#[inline]
pub(crate) fn photon_shot<R: Rng + ?Sized>(rng: &mut R, k: f32, electrons: f64) -> f32 {
    k * poisson(rng, electrons) as f32
}

/// Dark-current shot noise times the fixed pattern, the paper's
/// N_RS (1 + N_FP): N_RS = K Poisson(d) DN for `electrons` d of dark signal
/// (rate x law(t), [`DarkLaw::electrons`]), multiplied by (1 + N_FP) when
/// the pixel's fixed-pattern deviation `n_fp` is given (component F).
#[inline]
pub(crate) fn dark_shot<R: Rng + ?Sized>(
    rng: &mut R,
    k: f32,
    electrons: f64,
    n_fp: Option<f32>,
) -> f32 {
    let d = photon_shot(rng, k, electrons);
    match n_fp {
        Some(fp) => d * (1.0 + fp),
        None => d,
    }
}

/// Source-follower (read) noise, the paper's N_r: `sigma` (the pixel's
/// sigma_r in DN) times a standard Gaussian or Tukey-lambda draw.
#[inline]
pub(crate) fn read_noise<R: Rng + ?Sized>(rng: &mut R, sigma: f32, dist: ReadDist) -> f32 {
    let z = match dist {
        ReadDist::Gaussian => rng.sample::<f32, _>(StandardNormal),
        ReadDist::Tukey { lambda } => tukey::quantile(open01(rng), lambda as f64) as f32,
    };
    sigma * z
}

/// Row noise, the paper's N_H: one N(0, `sigma`^2) value per sensor row for
/// `rows` rows, drawn from per-row streams of `seed` (`lane` keeps two
/// users of one seed apart), so the values do not depend on the thread
/// count.
pub(crate) fn row_noise(seed: u64, rows: usize, sigma: f32, lane: u64) -> Vec<f32> {
    (0..rows)
        .map(|r| {
            let z: f32 = stream(seed, Domain::Row, r as u64, lane).sample(StandardNormal);
            z * sigma
        })
        .collect()
}

/// Quantisation noise, the paper's N_q: uniform on (-q/2, q/2) for a step of
/// `q` DN. (The virtual sensor quantises by rounding instead, as an ADC does.)
#[inline]
pub(crate) fn quantisation<R: Rng + ?Sized>(rng: &mut R, q: f32) -> f32 {
    q * (open01(rng) as f32 - 0.5)
}

impl NoiseModel {
    /// Foi's Poisson-Gaussian model: shot noise and a Gaussian read noise.
    pub(crate) fn poisson_gaussian(profile: &CameraProfile, p: &CaptureParams) -> NoiseModel {
        NoiseModel {
            k: p.k as f32,
            read: ReadDist::Gaussian,
            maps: PixelMaps {
                bias: Map::Scalar(0.0),
                sigma_read: Map::Scalar(p.sigma_gauss as f32),
                dark_rate: Map::Scalar(0.0),
                n_fp: Map::Scalar(0.0),
                dark_law: DarkLaw::Sqrt,
            },
            row_sigma: 0.0,
            quant_step: 1.0,
            components: Components::PG,
            dn_range: profile.dn_range as f32,
            black: profile.black.map(|b| b as f32),
            bank: None,
        }
    }

    /// ELD's model: shot, Tukey-lambda (or Gaussian) read, row, quantisation,
    /// per-channel colour bias.
    pub(crate) fn eld(profile: &CameraProfile, p: &CaptureParams, tukey: bool) -> NoiseModel {
        let (read, sigma) = if tukey {
            (
                ReadDist::Tukey {
                    lambda: p.tukey_lambda as f32,
                },
                p.sigma_tukey,
            )
        } else {
            (ReadDist::Gaussian, p.sigma_gauss)
        };
        NoiseModel {
            k: p.k as f32,
            read,
            maps: PixelMaps {
                bias: Map::Plane(p.bias.map(|b| b as f32)),
                sigma_read: Map::Scalar(sigma as f32),
                dark_rate: Map::Scalar(0.0),
                n_fp: Map::Scalar(0.0),
                dark_law: DarkLaw::Sqrt,
            },
            row_sigma: p.sigma_row as f32,
            quant_step: 1.0,
            components: Components::ELD,
            dn_range: profile.dn_range as f32,
            black: profile.black.map(|b| b as f32),
            bank: None,
        }
    }

    /// The paper's composite, D = K (I + N_s) + N_RS (1 + N_FP) + N_H +
    /// N_r + N_q, with the components `components` (letters P A F G H Q).
    /// `maps` (b, sigma_r, dark rate, N_FP per pixel) come from a calibration; without one the
    /// profile's global values are used (Gaussian read at the ISO's sigma,
    /// per-channel dark-level offset, the profile's dark current if measured).
    /// `global` is the "noD" ablation: per-pixel maps replaced by their means.
    pub fn pgrf(
        profile: &CameraProfile,
        p: &CaptureParams,
        maps: Option<PixelMaps>,
        components: Components,
        global: bool,
    ) -> NoiseModel {
        let maps = maps.unwrap_or_else(|| {
            let (law, rate) = profile
                .dark_current
                .as_ref()
                .map(|d| (d.law, d.rate as f32))
                .unwrap_or((DarkLaw::Sqrt, 0.0));
            PixelMaps {
                bias: Map::Plane(p.bias.map(|b| b as f32)),
                sigma_read: Map::Scalar(p.sigma_gauss as f32),
                dark_rate: Map::Scalar(rate),
                n_fp: Map::Scalar(0.0),
                dark_law: law,
            }
        });
        NoiseModel {
            k: p.k as f32,
            read: ReadDist::Gaussian,
            maps: if global { maps.global() } else { maps },
            row_sigma: p.sigma_row as f32,
            quant_step: 1.0,
            components,
            dn_range: profile.dn_range as f32,
            black: profile.black.map(|b| b as f32),
            bank: None,
        }
    }

    fn validate(&self, clean: &ArrayView3<f32>, c: &Capture) -> Result<()> {
        let s = clean.shape();
        if s.len() != 3 || s[0] != 4 || s[1] == 0 || s[2] == 0 {
            return Err(NoiseError::ImageShape { shape: s.to_vec() });
        }
        if !(c.ratio.is_finite() && c.ratio > 0.0) {
            return Err(NoiseError::Setting {
                name: "exposure ratio",
                must: "> 0",
                value: c.ratio,
            });
        }
        if !(c.exposure_s.is_finite() && c.exposure_s >= 0.0) {
            return Err(NoiseError::Setting {
                name: "exposure time",
                must: ">= 0 s",
                value: c.exposure_s,
            });
        }
        if !(self.k.is_finite() && self.k > 0.0) {
            return Err(NoiseError::Setting {
                name: "system gain K",
                must: "> 0",
                value: self.k,
            });
        }
        for (name, value) in [
            ("row sigma", self.row_sigma),
            ("quantisation step", self.quant_step),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(NoiseError::Setting {
                    name,
                    must: ">= 0",
                    value,
                });
            }
        }
        if c.plane_rows.iter().any(|&r| r > 1) {
            return Err(NoiseError::PlaneRows { rows: c.plane_rows });
        }
        self.maps.check((s[1], s[2]))
    }

    /// The composite model, per pixel: synthesise the noisy capture of
    /// `clean` (normalised, packed) taken `ratio` times darker, and return it
    /// multiplied back by the ratio, in the same normalised units (what a
    /// low-light pipeline feeds a denoiser). With I = clean x dn_range /
    /// ratio / K electrons, each pixel is, in DN,
    ///
    /// ```text
    /// D = K (I + N_s)         photon_shot        (P; I passes through without P)
    ///   + N_RS (1 + N_FP)     dark_shot          (A; the factor with F)
    ///   + b(x, y)             fixed-pattern offset (F)
    ///   + N_r                 read_noise         (G)
    ///   + N_H                 row_noise          (H)
    ///   + N_q                 quantisation       (Q)
    /// ```
    ///
    /// clipped to [-black, white - black], in this order of draws.
    /// Deterministic in `capture.seed`, whatever the number of threads.
    pub fn sample(&self, clean: ArrayView3<f32>, capture: &Capture) -> Result<Array3<f32>> {
        self.sample_with(clean, capture, false)
    }

    /// [`NoiseModel::sample`] of `clean` clipped to [0, 1] (as a pair's
    /// target is), each value as it is read: no clipped copy of the frame.
    pub fn sample_clipped(&self, clean: ArrayView3<f32>, capture: &Capture) -> Result<Array3<f32>> {
        self.sample_with(clean, capture, true)
    }

    fn sample_with(
        &self,
        clean: ArrayView3<f32>,
        capture: &Capture,
        clip: bool,
    ) -> Result<Array3<f32>> {
        self.validate(&clean, capture)?;
        let clean = clean.as_standard_layout();
        let src = clean.as_slice().expect("standard layout");
        let (ph, pw) = (clean.shape()[1], clean.shape()[2]);
        let c = self.components;

        // A bank's residuals stand for read, row and quantisation noise.
        let bank = (self.bank.as_ref())
            .filter(|_| c.read || c.row || c.quant)
            .map(|b| (b.as_ref(), b.draw(capture.seed, ph, pw)));
        // Row noise: one value per sensor row, shared by the planes on it.
        let rows: Vec<f32> = if c.row && self.row_sigma > 0.0 && bank.is_none() {
            row_noise(capture.seed, 2 * ph, self.row_sigma, 0)
        } else {
            vec![0.0; 2 * ph]
        };
        let draw = RowDraw {
            model: self,
            bank: bank.as_ref().map(|(b, d)| (*b, d)),
            to_dn: self.dn_range / capture.ratio,
            from_dn: capture.ratio / self.dn_range,
            inv_k: 1.0 / self.k as f64,
            dark_time: self.maps.dark_law.electrons(1.0, capture.exposure_s as f64) as f32,
            lo: self.black.map(|b| -b).unwrap_or(f32::NEG_INFINITY),
            pw,
            clip,
        };
        // Non-finite inputs (clean pixels, per-pixel map values) are caught
        // in the loop instead of by extra passes over ~290 MB (a separate scan
        // of the clean image cost 12% of the frame time).
        let bad = AtomicBool::new(false);
        let mut out = vec![0.0f32; src.len()];
        out.par_chunks_mut(pw).enumerate().for_each(|(block, dst)| {
            let (plane, i) = (block / ph, block % ph);
            let mut rng = stream(capture.seed, Domain::Pixel, plane as u64, i as u64);
            let row_off = rows[2 * i + capture.plane_rows[plane]];
            let srow = &src[block * pw..(block + 1) * pw];
            if !draw.row(&mut rng, (plane, i), row_off, srow, dst) {
                bad.store(true, Ordering::Relaxed);
            }
        });
        if bad.into_inner() {
            return Err(NoiseError::NonFinite);
        }
        Ok(Array3::from_shape_vec((4, ph, pw), out).expect("shape"))
    }
}

/// What [`NoiseModel::sample`] draws each packed row with: the model and
/// the capture's constants.
struct RowDraw<'a> {
    model: &'a NoiseModel,
    bank: Option<(&'a crate::bank::NoiseBank, &'a crate::bank::BankDraw)>,
    to_dn: f32,
    from_dn: f32,
    inv_k: f64,
    dark_time: f32,
    lo: f32,
    pw: usize,
    /// Clip each clean value to [0, 1] as it is read.
    clip: bool,
}

impl RowDraw<'_> {
    /// Row `i` of `plane` (clean `srow`, normalised) drawn into `dst` with
    /// `rng`, the row noise `row_off` added, in the order of the model's
    /// draws; false when a value came out non-finite.
    #[inline]
    fn row<R: Rng>(
        &self,
        rng: &mut R,
        (plane, i): (usize, usize),
        row_off: f32,
        srow: &[f32],
        dst: &mut [f32],
    ) -> bool {
        let (model, pw) = (self.model, self.pw);
        let (c, m, k) = (model.components, &model.maps, model.k);
        let q = model.quant_step;
        let mut row_ok = true;
        let base = i * pw;
        let sig_row = m.sigma_read.row(plane, i, pw);
        let bias_row = m.bias.row(plane, i, pw);
        let dark_row = m.dark_rate.row(plane, i, pw);
        let fp_row = m.n_fp.row(plane, i, pw);
        // The bank's residuals stand for N_r + N_H + N_q: written into dst
        // first, added per pixel below.
        if let Some((b, d)) = self.bank {
            b.row_into(d, plane, i, dst);
        }
        let banked = self.bank.is_some();
        // Tukey read noise: each pixel's uniform is drawn in the loop, in
        // the model's order, and the row's quantiles are taken after it in
        // one vector loop ([`RowDraw::add_tukey`]); the loop leaves the
        // rest of the value in DN in `dst`.
        let tukey = self.tukey_lambda();
        let mut us = vec![0.0f64; if tukey.is_some() { pw } else { 0 }];
        for j in 0..pw {
            let s = self.signal(srow[j]);
            row_ok &= s.is_finite();
            let mut v = if c.photon {
                photon_shot(rng, k, s as f64 * self.inv_k)
            } else {
                s
            };
            if c.dark {
                v += self.dark(
                    rng,
                    (plane, base + j),
                    dark_row.map(|r| r[j]),
                    fp_row.map(|r| r[j]),
                );
            }
            if c.fixed_pattern {
                v += bias_row.map_or_else(|| m.bias.at(plane, base + j), |r| r[j]);
            }
            if banked {
                v += dst[j];
            } else {
                if tukey.is_some() {
                    us[j] = open01(rng);
                } else if c.read {
                    let sigma = sig_row.map_or_else(|| m.sigma_read.at(plane, base + j), |r| r[j]);
                    v += read_noise(rng, sigma, model.read);
                }
                if c.row {
                    v += row_off;
                }
                if c.quant {
                    v += quantisation(rng, q);
                }
            }
            if tukey.is_some() {
                dst[j] = v;
            } else {
                row_ok &= v.is_finite();
                dst[j] = self.recorded(v);
            }
        }
        if let Some(lambda) = tukey {
            row_ok &= self.add_tukey(&mut us, lambda, (plane, base), sig_row, dst);
        }
        row_ok
    }

    /// ELD's Tukey-lambda shape when the row draws that read noise itself
    /// (not from a bank).
    fn tukey_lambda(&self) -> Option<f64> {
        match self.model.read {
            ReadDist::Tukey { lambda } if self.model.components.read && self.bank.is_none() => {
                Some(lambda as f64)
            }
            _ => None,
        }
    }

    /// A clean value in DN of the capture (clipped to [0, 1] first when
    /// the draw clips).
    #[inline(always)]
    fn signal(&self, x: f32) -> f32 {
        let x = if self.clip { x.clamp(0.0, 1.0) } else { x };
        x * self.to_dn
    }

    /// The dark-current shot noise of pixel `at` of `plane` (component A,
    /// times 1 + N_FP with F): its rate and fixed-pattern deviation from the
    /// row's maps when given (`rate`, `fp`), else looked up; none where the
    /// pixel's dark signal is none.
    #[inline(always)]
    fn dark<R: Rng>(
        &self,
        rng: &mut R,
        (plane, at): (usize, usize),
        rate: Option<f32>,
        fp: Option<f32>,
    ) -> f32 {
        let (c, m) = (self.model.components, &self.model.maps);
        let e = rate.unwrap_or_else(|| m.dark_rate.at(plane, at)) * self.dark_time;
        if e > 0.0 {
            let fp = c
                .fixed_pattern
                .then(|| fp.unwrap_or_else(|| m.n_fp.at(plane, at)));
            dark_shot(rng, self.model.k, e as f64, fp)
        } else {
            0.0
        }
    }

    /// A value in DN as the capture records it: clipped to the ADC's range
    /// [-black, white - black], on the normalised scale amplified by the
    /// ratio.
    #[inline(always)]
    fn recorded(&self, v: f32) -> f32 {
        v.clamp(self.lo, self.model.dn_range) * self.from_dn
    }

    /// The Tukey-lambda read noise of the row starting at pixel `base` of
    /// `plane` (its sigma_r row `sig_row` when the map has rows) added to
    /// `dst` (the rest of each value, in DN): the quantiles of the row's
    /// uniforms `us` times each pixel's sigma_r, then what the loop leaves
    /// for this pass ([`RowDraw::recorded`]); false when a value came out
    /// non-finite.
    fn add_tukey(
        &self,
        us: &mut [f64],
        lambda: f64,
        (plane, base): (usize, usize),
        sig_row: Option<&[f32]>,
        dst: &mut [f32],
    ) -> bool {
        tukey::quantiles_in_place(us, lambda);
        let m = &self.model.maps;
        let mut ok = true;
        for (j, (d, &q)) in dst.iter_mut().zip(us.iter()).enumerate() {
            let sigma = sig_row.map_or_else(|| m.sigma_read.at(plane, base + j), |r| r[j]);
            let v = *d + sigma * q as f32;
            ok &= v.is_finite();
            *d = self.recorded(v);
        }
        ok
    }
}
