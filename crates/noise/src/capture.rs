//! A simulated dark capture of a clean frame: what the camera would have
//! recorded with `ratio` times less light, at a given ISO and exposure time.
//!
//! The demo, `pgrf make-dataset` and tests all need a noisy RAW that a
//! denoiser can be run on exactly as on a real one: un-amplified, in the
//! clean frame's mosaic and levels, with ISO and exposure in its metadata so
//! that the ratio can be read back from EXIF. The noise is the training
//! pairs' own synthesis (the same pack, the same model, the same seed
//! streams), so a network sees at inference what it was trained on.

use crate::error::{NoiseError, Result};
use crate::pair::{ExposureSpec, PairSpec, RatioSpec};
use crate::{CameraProfile, ModelKind};
use ndarray::Array3;
use pgrf_raw::{pack_normalized, unpack_normalized, RawFrame};

/// What the camera records of a synthesised pair's noisy image: the pair is
/// amplified by the exposure ratio, as networks see it; the sensor holds it
/// un-amplified, clipped at white (1.0), with the read noise around black
/// kept (values below black stay, down to 0 DN on unpacking), as a real
/// dark frame has them.
pub fn recorded(noisy_amplified: &ndarray::Array3<f32>, ratio: f32) -> ndarray::Array3<f32> {
    ndarray::Zip::from(noisy_amplified).par_map_collect(|&v| (v / ratio).min(1.0))
}

/// How the dark frame is taken.
#[derive(Clone, Debug)]
pub struct DarkCapture {
    /// The camera whose noise is simulated.
    pub profile: CameraProfile,
    /// The noise model.
    pub model: ModelKind,
    /// ISO of the dark frame: selects the profile's parameters and is
    /// written to its EXIF.
    pub iso: u32,
    /// Exposure time of the dark frame, written to its EXIF.
    pub exposure_s: f64,
    /// How many times less light than the clean frame (> 0).
    pub ratio: f32,
    /// Seed of every random draw; the same seed gives the same frame.
    pub seed: u64,
}

impl DarkCapture {
    /// The dark frame of `clean`: noise added to clean / ratio in the
    /// model's physics, clipped at white, unpacked to `clean`'s mosaic,
    /// levels and metadata, with this capture's ISO and exposure.
    pub fn take(&self, clean: &RawFrame) -> Result<RawFrame> {
        if !(self.ratio.is_finite() && self.ratio > 0.0) {
            return Err(NoiseError::Setting {
                name: "ratio",
                must: "a positive number",
                value: self.ratio,
            });
        }
        let raw = |error: pgrf_raw::RawError| NoiseError::Frame { error };
        let mut spec = PairSpec::new(self.profile.clone(), self.model);
        spec.iso = Some(self.iso);
        spec.ratio = RatioSpec::Fixed(self.ratio);
        spec.exposure = ExposureSpec::Fixed(self.exposure_s as f32);
        let packed = pack_normalized(clean, true).map_err(raw)?;
        let plane_rows = clean.cfa.offsets().map(|(r, _)| r);
        let pair = spec.synthesize(packed.view(), plane_rows, self.seed)?;
        let dark = recorded(&pair.noisy, self.ratio);
        let mut out = unpack_normalized(dark.view(), clean).map_err(raw)?;
        out.iso = Some(self.iso);
        out.exposure_s = Some(self.exposure_s);
        Ok(out)
    }

    /// The dark-level offset every frame of [`DarkCapture::take`] on
    /// `clean` carries, packed like `clean` (`(4, H/2, W/2)`, R, G1, B, G2)
    /// in `clean`'s DN: the profile's black-level error at this ISO,
    /// rescaled from the profile's DN range to the frame's. It is what a
    /// calibration of the simulated camera measures (bias frames' mean minus
    /// the file's black level), so a calibrated pipeline subtracts it before
    /// amplifying, as `pgrf enhance --calib` does with a real one.
    pub fn dark_level_dn(&self, clean: &RawFrame) -> Result<Array3<f32>> {
        let bias = self.profile.params_at_iso(self.iso)?.bias;
        let dn = self.profile.dn_range;
        let level: [f32; 4] = std::array::from_fn(|p| {
            (bias[p] / dn * (clean.white as f64 - clean.black[p] as f64)) as f32
        });
        let (ph, pw) = (clean.height / 2, clean.width / 2);
        Ok(Array3::from_shape_fn((4, ph, pw), |(p, _, _)| level[p]))
    }
}
