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
use crate::rng::{open01, stream, Domain};
use ndarray::{Array3, ArrayView3};

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RatioSpec {
    Fixed(f32),
    Uniform { lo: f32, hi: f32 },
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
    Fixed(f32),
    /// ln t uniform between the bounds, seconds.
    LogUniform {
        lo: f32,
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

#[derive(Clone, Debug)]
pub struct PairSpec {
    pub profile: CameraProfile,
    pub kind: ModelKind,
    /// Components for the PGRF model (P-G and ELD have fixed sets).
    pub components: Components,
    /// "noD": replace per-pixel maps by their means.
    pub global: bool,
    /// ELD read noise: Tukey-lambda (true) or Gaussian.
    pub tukey: bool,
    pub maps: Option<PixelMaps>,
    /// Fixed ISO, or None to draw parameters from the profile's ELD distribution.
    pub iso: Option<u32>,
    pub ratio: RatioSpec,
    pub exposure: ExposureSpec,
}

/// One synthesised pair.
#[derive(Clone, Debug)]
pub struct Pair {
    /// Noisy capture multiplied back by the ratio, normalised units.
    pub noisy: Array3<f32>,
    /// The clean target, clipped to [0, 1].
    pub clean: Array3<f32>,
    pub ratio: f32,
    pub exposure_s: f32,
    pub params: CaptureParams,
}

impl PairSpec {
    pub fn new(profile: CameraProfile, kind: ModelKind) -> PairSpec {
        PairSpec {
            profile,
            kind,
            components: Components::ALL,
            global: false,
            tukey: true,
            maps: None,
            iso: None,
            ratio: RatioSpec::default(),
            exposure: ExposureSpec::default(),
        }
    }

    /// Resolve the model for one capture.
    pub fn model(&self, seed: u64) -> Result<(NoiseModel, CaptureParams)> {
        let params = match self.iso {
            Some(iso) => self.profile.params_at_iso(iso)?,
            None => self.profile.sample_params(seed),
        };
        let model = match self.kind {
            ModelKind::PoissonGaussian => NoiseModel::poisson_gaussian(&self.profile, &params),
            ModelKind::Eld => NoiseModel::eld(&self.profile, &params, self.tukey),
            ModelKind::Pgrf => NoiseModel::pgrf(
                &self.profile,
                &params,
                self.maps.clone(),
                self.components,
                self.global,
            ),
        };
        Ok((model, params))
    }

    /// Draw ratio and exposure for `seed`.
    pub fn conditions(&self, seed: u64) -> Result<(f32, f32)> {
        let mut rng = stream(seed, Domain::Params, 1, 0);
        let ratio = match self.ratio {
            RatioSpec::Fixed(r) => r,
            RatioSpec::Uniform { lo, hi } => {
                if !(lo > 0.0 && hi >= lo) {
                    return Err(NoiseError::Invalid(format!(
                        "ratio range {lo}..{hi} is not positive and ordered"
                    )));
                }
                lo + (hi - lo) * open01(&mut rng) as f32
            }
        };
        let exposure = match self.exposure {
            ExposureSpec::Fixed(t) => t,
            ExposureSpec::LogUniform { lo, hi } => {
                if !(lo > 0.0 && hi >= lo) {
                    return Err(NoiseError::Invalid(format!(
                        "exposure range {lo}..{hi} is not positive and ordered"
                    )));
                }
                (lo.ln() + (hi.ln() - lo.ln()) * open01(&mut rng) as f32).exp()
            }
        };
        Ok((ratio, exposure))
    }

    /// Synthesise one pair from a packed normalised clean image.
    pub fn synthesize(
        &self,
        clean: ArrayView3<f32>,
        plane_rows: [usize; 4],
        seed: u64,
    ) -> Result<Pair> {
        let (ratio, exposure_s) = self.conditions(seed)?;
        let (model, params) = self.model(seed)?;
        let clean = clean.mapv(|v| v.clamp(0.0, 1.0));
        let noisy = model.sample(
            clean.view(),
            &Capture {
                ratio,
                exposure_s,
                plane_rows,
                seed,
            },
        )?;
        Ok(Pair {
            noisy,
            clean,
            ratio,
            exposure_s,
            params,
        })
    }
}
