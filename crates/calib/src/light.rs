//! A light frame (a photo) made ready for a denoiser with a calibration:
//! the calibration checked to be of the photo's camera, ISO, filter layout
//! and size, its dark shading for the photo's exposure computed (what is
//! subtracted before amplifying), and its defective pixels replaced from
//! their neighbours (cosmetic correction). `pgrf enhance --calib` does this
//! to every photo.

use crate::{CalibError, Calibration};
use ndarray::Array3;
use pgrf_raw::RawFrame;

/// Why a calibration could not be applied to a photo.
#[derive(Debug, thiserror::Error)]
pub enum LightError {
    /// The calibration is of another camera or ISO (refused unless forced),
    /// or of another filter layout (always refused).
    #[error(transparent)]
    Mismatch(CalibError),
    /// The calibration's size is not the photo's.
    #[error(
        "calibration is {}x{}, the photo {}x{}",
        calibration.0, calibration.1, photo.0, photo.1
    )]
    Size {
        /// The calibration's width and height in pixels.
        calibration: (usize, usize),
        /// The photo's width and height in pixels.
        photo: (usize, usize),
    },
    /// The dark shading could not be computed for the photo's exposure
    /// time (not a non-negative number of seconds).
    #[error(transparent)]
    Shading(CalibError),
}

/// What the calibration leaves for the denoiser's input.
#[derive(Clone, Debug)]
pub struct PreparedLight {
    /// The expected dark level above black in DN per packed pixel for the
    /// photo's exposure ([`Calibration::dark_shading_dn`]), subtracted
    /// before the photo is amplified.
    pub dark_dn: Array3<f32>,
    /// How many defective pixels were replaced in the photo.
    pub defects_corrected: usize,
}

impl Calibration {
    /// Check this calibration against `frame` (camera and ISO unless
    /// `force`, filter layout, size), compute the dark shading for its
    /// exposure (none recorded: 0 s) and replace its defective pixels in
    /// place.
    pub fn prepare_light(
        &self,
        frame: &mut RawFrame,
        force: bool,
    ) -> Result<PreparedLight, LightError> {
        self.check_matches(&frame.make, &frame.model, frame.iso, force)
            .and_then(|()| self.check_layout(frame))
            .map_err(LightError::Mismatch)?;
        if (self.meta.width, self.meta.height) != (frame.width, frame.height) {
            return Err(LightError::Size {
                calibration: (self.meta.width, self.meta.height),
                photo: (frame.width, frame.height),
            });
        }
        let dark_dn = self
            .dark_shading_dn(frame.exposure_s.unwrap_or(0.0))
            .map_err(LightError::Shading)?;
        let defects_corrected = self.correct_defects(frame);
        Ok(PreparedLight {
            dark_dn,
            defects_corrected,
        })
    }
}
