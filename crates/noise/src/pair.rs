//! Training pairs: a clean long exposure in, (noisy x ratio, clean) out.
//!
//! Follows ELD/SID: the clean raw (normalised, clipped to [0, 1] — values
//! beyond are clipped highlights or noise below black) is divided by an
//! exposure ratio drawn from U(100, 300) or fixed, pushed through a noise
//! model at the camera's ISO or at ELD-sampled parameters, clipped to the
//! ADC range, and multiplied back. Every random choice comes from the seed.

use crate::components::Components;
use crate::error::{NoiseError, Result};
use crate::maps::PixelMaps;
use crate::model::{Capture, ModelKind, NoiseModel};
use crate::params::CaptureParams;
use crate::profile::CameraProfile;
use ndarray::{Array3, ArrayView3};
use pgrf_core::seed::{open01, stream, Domain};

/// The exposure ratios a user may give (`--ratio` of `enhance`, `synth`
/// and `eval`): from 1 (a capture as bright as its reference) to 10000, a
/// capture 13.3 stops darker. SID and ELD use 100 to 300; a ratio of 1e30
/// (which made `synth` write an exposure of 1.7e28 s) or 1e-30 means
/// nothing a camera records.
pub const RATIO_RANGE: std::ops::RangeInclusive<f32> = 1.0..=10_000.0;

/// An exposure ratio outside [`RATIO_RANGE`] (or not a number), with the
/// flag or field that gave it.
#[derive(Clone, Debug, PartialEq)]
pub struct RatioError {
    /// The flag or field that gave it ("--ratio", "ratio").
    pub flag: String,
    /// The ratio given.
    pub ratio: f32,
}

impl std::fmt::Display for RatioError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} {}: the exposure ratio must be from {} to {} (a capture at most {} times darker than its reference; SID and ELD use 100 to 300)",
            self.flag,
            shown(self.ratio),
            RATIO_RANGE.start(),
            RATIO_RANGE.end(),
            RATIO_RANGE.end()
        )
    }
}

impl std::error::Error for RatioError {}

/// `ratio`, given with `flag`, when it lies in [`RATIO_RANGE`]; else the
/// error naming the flag and the value.
pub fn ratio_in_range(flag: &str, ratio: f32) -> std::result::Result<f32, RatioError> {
    if ratio.is_finite() && RATIO_RANGE.contains(&ratio) {
        return Ok(ratio);
    }
    Err(RatioError {
        flag: flag.to_string(),
        ratio,
    })
}

/// `v` as typed: its shortest f32 form, in scientific notation beyond
/// ordinary magnitudes (`1e30`, not the f64 widening's 1.0000000150474662e30).
fn shown(v: f32) -> String {
    let a = v.abs();
    if v.is_finite() && a != 0.0 && !(1e-4..1e9).contains(&a) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// How each pair's exposure ratio (clean light / noisy light, > 0) is chosen;
/// the default is ELD/SID's U(100, 300).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RatioSpec {
    /// The same ratio for every pair.
    Fixed(f32),
    /// Drawn uniformly in [lo, hi] from each pair's seed.
    Uniform {
        /// Smallest ratio.
        lo: f32,
        /// Largest ratio.
        hi: f32,
    },
    /// ln ratio drawn uniformly in [ln lo, ln hi]: every factor of the range
    /// equally often (a camera's own noise at ratio 1 as often as x100-x300),
    /// where the uniform draw puts 94 % of 1..300 above x20.
    LogUniform {
        /// Smallest ratio.
        lo: f32,
        /// Largest ratio.
        hi: f32,
    },
}

impl Default for RatioSpec {
    fn default() -> Self {
        RatioSpec::Uniform {
            lo: 100.0,
            hi: 300.0,
        }
    }
}

/// Exposure time of the noisy capture (drives dark current).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ExposureSpec {
    /// The same exposure time for every pair, seconds.
    Fixed(f32),
    /// ln t uniform between the bounds, seconds.
    LogUniform {
        /// Shortest exposure, seconds.
        lo: f32,
        /// Longest exposure, seconds.
        hi: f32,
    },
}

impl Default for ExposureSpec {
    fn default() -> Self {
        // The short exposures of SID/ELD-style captures: 1/30 s to 1 s.
        ExposureSpec::LogUniform {
            lo: 1.0 / 30.0,
            hi: 1.0,
        }
    }
}

/// The recipe for synthesising training pairs from clean images: camera
/// profile, noise model and its options, optional calibration maps, and how
/// ISO, ratio and exposure are chosen. [`PairSpec::new`] gives ELD's defaults;
/// change the public fields to vary them.
#[derive(Clone, Debug)]
pub struct PairSpec {
    pub(crate) profile: CameraProfile,
    /// Which noise model synthesises the noisy image.
    pub kind: ModelKind,
    /// Components for the PGRF model (P-G and ELD have fixed sets).
    pub components: Components,
    /// "noD": replace per-pixel maps by their means.
    pub global: bool,
    /// ELD read noise: Tukey-lambda (true) or Gaussian.
    pub tukey: bool,
    /// Per-pixel calibration maps for the PGRF model (None: the profile's
    /// global values); packed `(4, H/2, W/2)` like the clean images.
    pub maps: Option<PixelMaps>,
    /// The sensor's residual noise frames, drawn by the PGRF model instead
    /// of its parametric read, row and quantisation noise
    /// ([`crate::bank`]; None: parametric).
    pub bank: Option<std::sync::Arc<crate::bank::NoiseBank>>,
    /// Global numbers measured with `maps` (gain, row noise, DN scale): they
    /// replace the profile's, because per-pixel maps are only meaningful on
    /// the scale and at the gain they were measured with.
    pub measured: Option<Measured>,
    /// Fixed ISO, or None to draw parameters from the profile's ELD distribution.
    pub iso: Option<u32>,
    /// With no fixed ISO: draw the gain only between these ISOs' (inclusive)
    /// instead of over the profile's whole range.
    pub iso_range: Option<(u32, u32)>,
    /// With neither ISO setting: draw the gain K (DN per electron) in this
    /// range instead of the profile's whole one (how a [`crate::mix::PairMix`]
    /// gives its other cameras the first one's ISO range).
    pub gain_range: Option<(f64, f64)>,
    /// How the exposure ratio is chosen.
    pub ratio: RatioSpec,
    /// How the noisy capture's exposure time (dark current) is chosen.
    pub exposure: ExposureSpec,
    /// The camera's dark-level offset (the profile's black-level error, or
    /// ELD's drawn colour bias) is taken as calibrated and subtracted, so
    /// the captures carry none: what a denoiser sees after `pgrf enhance
    /// --calib` (or in the synthetic protocol). Per-pixel calibration maps
    /// keep their own fixed pattern.
    pub calibrated_dark_level: bool,
    /// Without [`PairSpec::calibrated_dark_level`]: the share (0..1) of
    /// captures drawn as calibrated all the same, so that one network learns
    /// both the raw camera's offset and its absence (issue 36: a model of
    /// uncalibrated captures alone darkens calibrated ones).
    pub calibrated_share: f64,
}

/// Global results of a calibration that accompany its per-pixel maps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measured {
    /// System gain K, DN per electron.
    pub k: f64,
    /// Row-noise standard deviation sigma_H, DN.
    pub row_sigma: f64,
    /// white - black of the calibrated camera, DN.
    pub dn_range: f64,
    /// Black level of the calibrated camera, DN (results are clipped at 0 DN above it).
    pub black: f64,
}

/// One synthesised pair.
#[derive(Clone, Debug)]
pub struct Pair {
    /// Noisy capture multiplied back by the ratio, normalised units.
    pub noisy: Array3<f32>,
    /// The clean target, clipped to [0, 1].
    pub clean: Array3<f32>,
    /// The exposure ratio this pair was synthesised at.
    pub ratio: f32,
    /// Exposure time of the noisy capture, seconds.
    pub exposure_s: f32,
    /// The noise parameters (K, read and row sigmas, ...) the pair was drawn with.
    pub params: CaptureParams,
}

/// A noisy capture without its clean target ([`PairSpec::synthesize_noisy`]).
#[derive(Clone, Debug)]
pub struct NoisyDraw {
    /// Noisy capture multiplied back by the ratio, normalised units.
    pub noisy: Array3<f32>,
    /// The exposure ratio it was synthesised at.
    pub ratio: f32,
    /// Exposure time of the noisy capture, seconds.
    pub exposure_s: f32,
    /// The noise parameters it was drawn with.
    pub params: CaptureParams,
}

impl PairSpec {
    /// `kind` on `profile` with ELD's choices: all components, per-pixel
    /// effects from the profile (no maps), Tukey-lambda read noise for ELD,
    /// parameters drawn from the profile's ELD distribution (no fixed ISO),
    /// ratio U(100, 300), exposure log-uniform over 1/30..1 s.
    pub fn new(profile: CameraProfile, kind: ModelKind) -> PairSpec {
        PairSpec {
            profile,
            kind,
            components: Components::ALL,
            global: false,
            tukey: true,
            maps: None,
            bank: None,
            measured: None,
            iso: None,
            iso_range: None,
            gain_range: None,
            ratio: RatioSpec::default(),
            exposure: ExposureSpec::default(),
            calibrated_dark_level: false,
            calibrated_share: 0.0,
        }
    }

    /// Whether capture `seed` falls in [`PairSpec::calibrated_share`] (its own
    /// stream, so the other draws are those of a run without the share).
    fn drawn_calibrated(&self, seed: u64) -> bool {
        self.calibrated_share > 0.0
            && open01(&mut stream(seed, Domain::Params, 3, 0)) < self.calibrated_share
    }

    /// Resolve the model for one capture.
    pub(crate) fn model(&self, seed: u64) -> Result<(NoiseModel, CaptureParams)> {
        let mut params = match (self.iso, self.iso_range) {
            (Some(iso), _) => self.profile.params_at_iso(iso)?,
            (None, None) => self.profile.sample_params(seed, self.gain_range),
            (None, Some((lo, hi))) => {
                let range = self.k_range(lo, hi)?;
                self.profile.sample_params(seed, Some(range))
            }
        };
        if self.calibrated_dark_level || self.drawn_calibrated(seed) {
            params.bias = [0.0; 4];
        }
        let mut profile = std::borrow::Cow::Borrowed(&self.profile);
        if let Some(m) = self.measured {
            params.k = m.k;
            params.sigma_row = m.row_sigma;
            let p = profile.to_mut();
            p.dn_range = m.dn_range;
            p.black = Some(m.black);
        }
        let profile = profile.as_ref();
        let model = match self.kind {
            ModelKind::PoissonGaussian => NoiseModel::poisson_gaussian(profile, &params),
            ModelKind::Eld => NoiseModel::eld(profile, &params, self.tukey),
            ModelKind::Pgrf => NoiseModel {
                bank: self.bank.clone(),
                ..NoiseModel::pgrf(
                    profile,
                    &params,
                    self.maps.clone(),
                    self.components,
                    self.global,
                )
            },
        };
        Ok((model, params))
    }

    /// white - black in DN of the captures this spec draws: the
    /// calibration's when one was applied, else the profile's. Noise
    /// parameters in DN refer to this scale.
    pub fn dn_range(&self) -> f64 {
        self.measured
            .map(|m| m.dn_range)
            .unwrap_or(self.profile.dn_range)
    }

    /// The gains of ISO `lo` and `hi`, checked: ordered, and both within
    /// what the profile knows.
    pub fn k_range(&self, lo: u32, hi: u32) -> Result<(f64, f64)> {
        if lo == 0 || hi < lo {
            return Err(NoiseError::IsoRange { lo, hi });
        }
        let (a, b) = (
            self.profile.params_at_iso(lo)?.k,
            self.profile.params_at_iso(hi)?.k,
        );
        Ok((a.min(b), a.max(b)))
    }

    /// Draw (ratio, exposure time in seconds) for `seed`, as
    /// [`PairSpec::synthesize`] does.
    pub fn conditions(&self, seed: u64) -> Result<(f32, f32)> {
        let mut rng = stream(seed, Domain::Params, 1, 0);
        let ratio = match self.ratio {
            RatioSpec::Fixed(r) => r,
            RatioSpec::Uniform { lo, hi } | RatioSpec::LogUniform { lo, hi } => {
                if !(lo > 0.0 && hi >= lo) {
                    return Err(NoiseError::DrawRange {
                        name: "ratio",
                        lo,
                        hi,
                    });
                }
                let u = open01(&mut rng) as f32;
                if matches!(self.ratio, RatioSpec::LogUniform { .. }) {
                    (lo.ln() + (hi.ln() - lo.ln()) * u).exp().clamp(lo, hi)
                } else {
                    lo + (hi - lo) * u
                }
            }
        };
        let exposure = match self.exposure {
            ExposureSpec::Fixed(t) => t,
            ExposureSpec::LogUniform { lo, hi } => {
                if !(lo > 0.0 && hi >= lo) {
                    return Err(NoiseError::DrawRange {
                        name: "exposure",
                        lo,
                        hi,
                    });
                }
                (lo.ln() + (hi.ln() - lo.ln()) * open01(&mut rng) as f32).exp()
            }
        };
        Ok((ratio, exposure))
    }

    /// Synthesise one pair from a packed normalised clean image `(4, H/2, W/2)`
    /// in R, G1, B, G2 order; `plane_rows` is each plane's sensor-row parity
    /// (from the CFA, for row noise). Deterministic in `seed`.
    pub fn synthesize(
        &self,
        clean: ArrayView3<f32>,
        plane_rows: [usize; 4],
        seed: u64,
    ) -> Result<Pair> {
        let d = self.synthesize_noisy(clean, plane_rows, seed)?;
        Ok(Pair {
            noisy: d.noisy,
            clean: clean.mapv(|v| v.clamp(0.0, 1.0)),
            ratio: d.ratio,
            exposure_s: d.exposure_s,
            params: d.params,
        })
    }

    /// [`PairSpec::synthesize`] without the clean target's clipped copy:
    /// the same noisy capture, for callers that keep only it (`pgrf synth`,
    /// `pgrf.synth`), which saves a frame-sized copy.
    pub fn synthesize_noisy(
        &self,
        clean: ArrayView3<f32>,
        plane_rows: [usize; 4],
        seed: u64,
    ) -> Result<NoisyDraw> {
        let (ratio, exposure_s) = self.conditions(seed)?;
        let (model, params) = self.model(seed)?;
        let noisy = model.sample_clipped(
            clean,
            &Capture {
                ratio,
                exposure_s,
                plane_rows,
                seed,
            },
        )?;
        Ok(NoisyDraw {
            noisy,
            ratio,
            exposure_s,
            params,
        })
    }
}

#[cfg(test)]
mod ratio_tests {
    use super::{ratio_in_range, RatioError};

    /// The message of [`ratio_in_range`]'s refusal, or the ratio.
    fn check_ratio(flag: &str, ratio: f32) -> Result<f32, String> {
        ratio_in_range(flag, ratio).map_err(|e| e.to_string())
    }

    #[test]
    fn ratios_outside_one_to_ten_thousand_are_refused_with_the_flag() {
        assert_eq!(check_ratio("--ratio", 1.0), Ok(1.0));
        assert_eq!(check_ratio("--ratio", 10_000.0), Ok(10_000.0));
        for bad in [
            1e30,
            1e-30,
            0.999,
            10_000.5,
            0.0,
            -3.0,
            f32::NAN,
            f32::INFINITY,
        ] {
            let e = check_ratio("--ratio", bad).unwrap_err();
            assert!(
                e.starts_with("--ratio ") && e.contains("from 1 to 10000"),
                "{e}"
            );
        }
        assert!(check_ratio("--ratio", 1e30)
            .unwrap_err()
            .starts_with("--ratio 1e30:"));
        assert!(check_ratio("--ratio", 1e-30)
            .unwrap_err()
            .starts_with("--ratio 1e-30:"));
        assert!(check_ratio("--ratio", 0.5)
            .unwrap_err()
            .starts_with("--ratio 0.5:"));
        let e = ratio_in_range("ratio", 0.5).unwrap_err();
        assert_eq!(
            e,
            RatioError {
                flag: "ratio".into(),
                ratio: 0.5
            }
        );
        assert_eq!(Err(e.to_string()), check_ratio("ratio", 0.5));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    fn clean() -> Array3<f32> {
        // Includes values outside [0, 1] that synthesis must clip.
        Array3::from_shape_fn((4, 64, 64), |(p, i, j)| {
            (p as f32 * 0.1 + i as f32 / 64.0 + j as f32 / 640.0) - 0.05
        })
    }

    #[test]
    fn pairs_are_reproducible_and_draw_their_conditions_in_range() {
        let mut spec = PairSpec::new(
            CameraProfile::built_in("sony-a7s2").unwrap(),
            ModelKind::Pgrf,
        );
        spec.iso = Some(3200);
        let c = clean();
        let a = spec.synthesize(c.view(), [0, 0, 1, 1], 11).unwrap();
        let b = spec.synthesize(c.view(), [0, 0, 1, 1], 11).unwrap();
        assert_eq!(a.noisy, b.noisy);
        assert_eq!((a.ratio, a.exposure_s), (b.ratio, b.exposure_s));
        assert!(a.clean.iter().all(|v| (0.0..=1.0).contains(v)));
        let mut ratios = Vec::new();
        for s in 0..200 {
            let (r, t) = spec.conditions(s).unwrap();
            assert!((100.0..=300.0).contains(&r));
            assert!((1.0 / 30.0..=1.0).contains(&t));
            ratios.push(r as f64);
        }
        // U(100, 300): mean 200, sd 57.7; 5 SE over 200 draws.
        let m = ratios.iter().sum::<f64>() / 200.0;
        assert!((m - 200.0).abs() < 5.0 * 57.7 / 200f64.sqrt(), "{m}");
    }

    /// The log-uniform draw: ln r uniform on [0, ln 300] (mean 2.852, sd
    /// 1.647; 5 SE over 400 draws), about half the draws below x20
    /// (ln 20 / ln 300 = 0.525, 5 SE = 0.125), none outside the range.
    #[test]
    fn log_uniform_ratios_spread_evenly_over_the_factors() {
        let mut spec = PairSpec::new(
            CameraProfile::built_in("sony-a7s2").unwrap(),
            ModelKind::Pgrf,
        );
        spec.ratio = RatioSpec::LogUniform { lo: 1.0, hi: 300.0 };
        let ln: Vec<f64> = (0..400)
            .map(|s| spec.conditions(s).unwrap().0)
            .inspect(|r| assert!((1.0..=300.0).contains(r), "{r}"))
            .map(|r| (r as f64).ln())
            .collect();
        let m = ln.iter().sum::<f64>() / 400.0;
        assert!((m - 2.852).abs() < 5.0 * 1.647 / 20.0, "mean ln r {m}");
        let below = ln.iter().filter(|&&l| l < 20f64.ln()).count() as f64 / 400.0;
        assert!((below - 0.525).abs() < 0.125, "below x20: {below}");
        spec.ratio = RatioSpec::LogUniform { lo: 0.0, hi: 300.0 };
        assert!(spec.conditions(0).is_err());
    }

    #[test]
    fn shot_noise_alone_is_unbiased_after_amplification() {
        let mut spec = PairSpec::new(
            CameraProfile::built_in("sony-a7s2").unwrap(),
            ModelKind::Pgrf,
        );
        spec.iso = Some(1600);
        spec.components = Components::parse("P").unwrap();
        spec.ratio = RatioSpec::Fixed(100.0);
        let flat = Array3::from_elem((4, 128, 128), 0.5f32);
        let p = spec.synthesize(flat.view(), [0, 0, 1, 1], 3).unwrap();
        let n = p.noisy.len() as f64;
        let mean = p.noisy.iter().map(|&v| v as f64).sum::<f64>() / n;
        // In DN of the short exposure: S = 0.5 * 15871 / 100, Var = K S; amplified back by 100/15871.
        let s = 0.5 * 15871.0 / 100.0;
        let se = (1.53008 * s / n).sqrt() * 100.0 / 15871.0;
        assert!((mean - 0.5).abs() < 5.0 * se, "{mean}");
    }

    #[test]
    fn calibrated_captures_carry_no_dark_level_offset() {
        // ELD-sampled parameters (no ISO): each capture draws one of the
        // A7S2's measured colour biases. Per plane over 16,384 samples of a
        // flat 0.3 at x100, the mean moves by ratio x bias / 15871 with the
        // offset and by nothing without it (noise SE ~4e-4 at the highest
        // gain; tolerance 3e-3).
        let mut spec = PairSpec::new(
            CameraProfile::built_in("sony-a7s2").unwrap(),
            ModelKind::Pgrf,
        );
        spec.ratio = RatioSpec::Fixed(100.0);
        let flat = Array3::from_elem((4, 128, 128), 0.3f32);
        let plane_means = |p: &Pair| -> Vec<f64> {
            p.noisy
                .outer_iter()
                .map(|v| v.iter().map(|&x| x as f64).sum::<f64>() / v.len() as f64)
                .collect()
        };
        let mut biased = 0;
        for seed in 0..6 {
            let raw = spec.synthesize(flat.view(), [0, 0, 1, 1], seed).unwrap();
            let mut cal_spec = spec.clone();
            cal_spec.calibrated_dark_level = true;
            let cal = cal_spec
                .synthesize(flat.view(), [0, 0, 1, 1], seed)
                .unwrap();
            assert_eq!(cal.params.bias, [0.0; 4]);
            assert_eq!(cal.params.k, raw.params.k, "the same draw otherwise");
            for (p, (mr, mc)) in plane_means(&raw).iter().zip(plane_means(&cal)).enumerate() {
                let off = 100.0 * raw.params.bias[p] / 15871.0;
                assert!(
                    (mr - 0.3 - off).abs() < 3e-3,
                    "seed {seed} plane {p}: {mr} vs {off}"
                );
                assert!(
                    (mc - 0.3).abs() < 3e-3,
                    "seed {seed} plane {p}: calibrated {mc}"
                );
            }
            biased += raw.params.bias.iter().any(|b| b.abs() > 1.0) as usize;
        }
        assert!(
            biased >= 2,
            "only {biased} of 6 draws had an offset over 1 DN"
        );
    }

    #[test]
    fn a_share_of_captures_is_drawn_calibrated() {
        // Share 0.3 over 1,000 seeded captures: among those whose draw has a
        // colour bias, the calibrated fraction is 0.3 within 4 binomial
        // standard errors (~0.06); every other parameter is the draw of the
        // spec without the share.
        let mut spec = PairSpec::new(
            CameraProfile::built_in("sony-a7s2").unwrap(),
            ModelKind::Pgrf,
        );
        let mut shared = spec.clone();
        shared.calibrated_share = 0.3;
        let (mut biased, mut zeroed) = (0usize, 0usize);
        for seed in 0..1000 {
            let (_, raw) = spec.model(seed).unwrap();
            let (_, drawn) = shared.model(seed).unwrap();
            assert_eq!(drawn.k, raw.k);
            assert_eq!(drawn.sigma_row, raw.sigma_row);
            if raw.bias != [0.0; 4] {
                biased += 1;
                if drawn.bias == [0.0; 4] {
                    zeroed += 1;
                } else {
                    assert_eq!(drawn.bias, raw.bias);
                }
            }
        }
        assert!(biased > 500, "{biased}");
        let f = zeroed as f64 / biased as f64;
        let se = (0.3 * 0.7 / biased as f64).sqrt();
        assert!((f - 0.3).abs() < 4.0 * se, "{f} of {biased}");
        spec.calibrated_share = 1.0;
        assert_eq!(spec.model(7).unwrap().1.bias, [0.0; 4]);
    }

    #[test]
    fn bad_ranges_are_errors() {
        let mut spec = PairSpec::new(
            CameraProfile::built_in("sony-a7s2").unwrap(),
            ModelKind::Eld,
        );
        spec.ratio = RatioSpec::Uniform {
            lo: 300.0,
            hi: 100.0,
        };
        assert!(spec.conditions(0).is_err());
        spec.ratio = RatioSpec::Fixed(100.0);
        spec.exposure = ExposureSpec::LogUniform { lo: 0.0, hi: 1.0 };
        assert!(spec.conditions(0).is_err());
    }
}

#[cfg(test)]
mod noisy_only_tests {
    use super::*;
    use crate::CameraProfile;

    /// Clipping each clean value as it is read draws, bit for bit, what
    /// the model draws from a clipped copy of the frame, for every model
    /// (ELD's Tukey read noise included) and a frame with values outside
    /// [0, 1]; and the pair's noisy capture is the one without its copy.
    #[test]
    fn synthesize_noisy_draws_what_synthesize_draws() {
        let clean = ndarray::Array3::from_shape_fn((4, 24, 40), |(p, y, x)| {
            -0.2 + 1.5 * ((p * 31 + y * 7 + x * 3) % 97) as f32 / 96.0
        });
        for kind in [ModelKind::PoissonGaussian, ModelKind::Eld, ModelKind::Pgrf] {
            let mut spec = PairSpec::new(CameraProfile::built_in("sony-a7s2").unwrap(), kind);
            spec.iso = Some(1600);
            spec.ratio = RatioSpec::Fixed(100.0);
            let (model, _) = spec.model(5).unwrap();
            let (ratio, exposure_s) = spec.conditions(5).unwrap();
            let c = Capture {
                ratio,
                exposure_s,
                plane_rows: [0, 0, 1, 1],
                seed: 5,
            };
            let copy = clean.mapv(|v| v.clamp(0.0, 1.0));
            let from_copy = model.sample(copy.view(), &c).unwrap();
            assert_eq!(
                from_copy,
                model.sample_clipped(clean.view(), &c).unwrap(),
                "{kind:?}"
            );
            assert_ne!(
                from_copy,
                model.sample(clean.view(), &c).unwrap(),
                "{kind:?}"
            );
            let pair = spec.synthesize(clean.view(), [0, 0, 1, 1], 5).unwrap();
            assert_eq!(pair.noisy, from_copy, "{kind:?}");
            let noisy = spec
                .synthesize_noisy(clean.view(), [0, 0, 1, 1], 5)
                .unwrap();
            assert_eq!(pair.noisy, noisy.noisy, "{kind:?}");
            assert_eq!(
                (pair.ratio, pair.exposure_s),
                (noisy.ratio, noisy.exposure_s)
            );
            assert!(pair.clean.iter().all(|v| (0.0..=1.0).contains(v)));
        }
    }
}
