//! Master frames for the astrophotographer's workflow: the mean of each
//! stack (bias, dark per exposure, flat per level) as a RAW frame of the
//! camera's own mosaic and levels, what DeepSkyStacker, Siril or
//! PixInsight take as master bias, dark and flat: FITS (32-bit float, the
//! mean unrounded) when the frames were FITS, DNG otherwise.

use crate::error::{CalibError, Result};
use crate::stack::{FrameKey, Stack};
use ndarray::Array3;
use pgrf_raw::{unpack_u16, RawFrame};

/// One master: the temporal mean of a stack's frames at one exposure.
#[derive(Clone, Debug)]
pub struct Master {
    /// File stem: `master_bias`, `master_dark_10s`, `master_flat_0.04s`.
    pub name: String,
    /// The exposure of its frames, s.
    pub exposure_s: f64,
    /// Frames averaged.
    pub frames: usize,
    /// The mean, packed `(4, H/2, W/2)`, DN with black.
    pub mean: Array3<f32>,
}

/// The masters of `stack` (`kind`: "bias", "dark" or "flat"), one per
/// exposure; the bias stack's has no exposure in its name.
pub(crate) fn masters_of(stack: &Stack, kind: &str) -> Vec<Master> {
    stack
        .groups
        .iter()
        .map(|g| Master {
            name: if kind == "bias" {
                "master_bias".into()
            } else {
                // Single precision's shortest form: 0.01, not the
                // 0.009999999776482582 a rational read into f32 becomes.
                format!("master_{kind}_{}s", g.exposure_s as f32)
            },
            exposure_s: g.exposure_s,
            frames: g.files.len(),
            mean: g.stats.mean().mapv(|v| v as f32),
        })
        .collect()
}

impl Master {
    /// The master as a RAW frame of the calibrated camera (`key`: size,
    /// CFA, levels, ISO, make and model), its mean rounded to whole DN: a
    /// mean of n frames is finer than a DN, but the DNG holds integers, and
    /// rounding adds 1/12 DN^2, far below any frame's noise.
    pub fn frame(&self, key: &FrameKey) -> Result<RawFrame> {
        let white = key.white as f32;
        let packed = self.mean.mapv(|v| v.round().clamp(0.0, white) as u16);
        unpack_u16(packed.view(), &self.template(key)?).map_err(|e| self.refused(e))
    }

    /// An empty frame of the calibrated camera with this master's metadata.
    fn template(&self, key: &FrameKey) -> Result<RawFrame> {
        let mut f = RawFrame::from_mosaic(
            key.width,
            key.height,
            vec![0; key.width * key.height],
            key.cfa,
            key.black,
            key.white,
        )
        .map_err(|e| self.refused(e))?;
        f.mono = key.mono;
        if key.fits {
            // The stacks' stored row order, which the master keeps.
            f.fits = Some(pgrf_raw::FitsHeader {
                row_order: Some(key.row_order),
                binning: key.binning,
                ..Default::default()
            });
        }
        f.iso = key.iso;
        f.exposure_s = Some(self.exposure_s);
        f.make = key.make.clone();
        f.model = key.model.clone();
        Ok(f)
    }

    /// The master as a FITS file: the mean unrounded (32-bit float,
    /// normalised to 0-1, so no SATURATE), rows in the stacks' stored order
    /// with the ROWORDER that says which, with IMAGETYP, NCOMBINE, the
    /// frames' exposure, ISO, `temperature_c` and the measured gain as
    /// EGAIN (electrons per ADU, 1 / `k`).
    pub fn fits(&self, key: &FrameKey, k: f64, temperature_c: Option<f32>) -> Result<Vec<u8>> {
        let mut template = self.template(key)?;
        template.temperature_c = temperature_c;
        let mosaic = crate::calibration::sensor_layout(&self.mean, key.cfa);
        let kind = match self.name.split('_').nth(1) {
            Some("bias") => "Master Bias",
            Some("dark") => "Master Dark",
            _ => "Master Flat",
        };
        pgrf_raw::encode_fits_master(&template, &mosaic, kind, self.frames, Some(1.0 / k))
            .map_err(|e| self.refused(e))
    }

    /// The RAW layer's refusal of this master.
    fn refused(&self, error: pgrf_raw::RawError) -> CalibError {
        CalibError::Master {
            master: self.name.clone(),
            error,
        }
    }
}

/// The defect map as a picture of the sensor (`key`'s size and CFA), one
/// pixel per photosite: good pixels black, hot red, dead blue, cold cyan,
/// defective columns yellow ([`crate::estimate::defect`]). Interleaved RGB
/// in [0, 1], row by row.
pub fn defect_picture(defects: &Array3<f32>, key: &FrameKey) -> Vec<f32> {
    use crate::estimate::defect;
    let (w, h) = (key.width, key.height);
    let mut rgb = vec![0.0f32; 3 * w * h];
    for (p, (dy, dx)) in key.cfa.offsets().into_iter().enumerate() {
        for ((i, j), &c) in defects.index_axis(ndarray::Axis(0), p).indexed_iter() {
            let colour = match c {
                x if x == defect::HOT => [1.0, 0.0, 0.0],
                x if x == defect::DEAD => [0.0, 0.3, 1.0],
                x if x == defect::COLD => [0.0, 1.0, 1.0],
                x if x == defect::COLUMN => [1.0, 1.0, 0.0],
                _ => continue,
            };
            let (y, x) = (2 * i + dy, 2 * j + dx);
            if y < h && x < w {
                rgb[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&colour);
            }
        }
    }
    rgb
}
