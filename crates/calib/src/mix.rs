//! The noise of synthetic pairs, built once for every command that makes
//! them (`pgrf train`, `pgrf search`, `pgrf synth`): a camera profile or a
//! weighted mix of profiles ([`pgrf_noise::mix::PairMix`]) with, for one
//! sensor, its per-pixel calibration file applied. Here because this is the
//! lowest crate that knows both the mix and the calibration.

use crate::calibration::Calibration;
use crate::error::CalibError;
use pgrf_noise::mix::PairMix;
use pgrf_noise::pair::{PairSpec, RatioSpec};
use pgrf_noise::{ModelKind, NoiseError};
use pgrf_raw::RawFrame;
use std::path::{Path, PathBuf};

/// What the pairs' noise is made of.
#[derive(Clone, Debug)]
pub struct MixSpec<'a> {
    /// A profile (built-in name, darktable:"MAKER MODEL", dng:FILE or JSON
    /// path) or a weighted mix `NAME[@WEIGHT],...`.
    pub profile: &'a str,
    /// The noise model.
    pub model: ModelKind,
    /// A fixed ISO (the first profile's), or None for drawn parameters.
    pub iso: Option<u32>,
    /// Without a fixed ISO: the ISO range the gain is drawn from.
    pub iso_range: Option<(u32, u32)>,
    /// The exposure ratios.
    pub ratio: RatioSpec,
    /// Captures without the camera's dark-level offset.
    pub calibrated_dark_level: bool,
    /// Otherwise the share of captures drawn as calibrated (0..1).
    pub calibrated_share: f64,
    /// A per-pixel calibration file for the (single) sensor.
    pub calibration: Option<&'a Path>,
    /// Draw read, row and quantisation noise from the calibration's noise
    /// bank ([`pgrf_noise::bank`]).
    pub noise_bank: bool,
    /// darktable's noiseprofiles.json for `darktable:` profiles (None:
    /// darktable's install is searched).
    pub darktable: Option<&'a Path>,
}

/// The mix, and the identity of the calibration applied (camera, ISO, file
/// name; [`Calibration::identity`]) when there was one.
pub struct CalibratedMix {
    /// The pairs' noise, one profile per capture.
    pub mix: PairMix,
    /// The calibration's identity, for the weight file's record.
    pub calibration: Option<String>,
}

/// Why the noise could not be built; callers name their own flags around
/// the first two.
#[derive(Debug, thiserror::Error)]
pub enum MixError {
    /// A profile of the mix could not be read or parsed.
    #[error(transparent)]
    Profile(NoiseError),
    /// A calibration (one sensor) was given with a mix of profiles.
    #[error("{}: a calibration describes one sensor, not a mix of profiles ({mix})", path.display())]
    CalibrationWithMix {
        /// The calibration file.
        path: PathBuf,
        /// The mix, in words.
        mix: String,
    },
    /// The calibration file could not be read.
    #[error(transparent)]
    Load(Box<CalibError>),
    /// The calibration is of another camera, ISO or CFA layout than the frame.
    #[error("{}: {cause}", path.display())]
    Mismatch {
        /// The calibration file.
        path: PathBuf,
        /// What differs (in the message, not a `source()`: one-line
        /// reports print the chain, which would say it twice).
        cause: Box<CalibError>,
    },
    /// The calibration's size is not the frame's.
    #[error("{}: calibration is {}x{}, the clean frame {}x{}", path.display(), calibration.0, calibration.1, frame.0, frame.1)]
    Size {
        /// The calibration file.
        path: PathBuf,
        /// Its width and height.
        calibration: (usize, usize),
        /// The frame's width and height.
        frame: (usize, usize),
    },
    /// A noise bank was asked for without a calibration, or the
    /// calibration has none.
    #[error("{}", match path {
        None => pgrf_noise::bank::NEEDS_CALIBRATION.to_string(),
        Some(p) => format!("--noise-bank: {} holds no noise bank (calibrated from fewer than two bias frames, or by a pgrf before banks): calibrate again", p.display()),
    })]
    NoBank {
        /// The calibration without one.
        path: Option<PathBuf>,
    },
    /// The calibration's maps could not be applied to the noise model.
    #[error("--calib {}: {cause}", path.display())]
    Apply {
        /// The calibration file.
        path: PathBuf,
        /// Why not (in the message only, like [`MixError::Mismatch`]'s).
        cause: Box<CalibError>,
    },
}

/// The noise of `spec`: the profiles' mix with the calibration applied.
pub fn build(spec: &MixSpec) -> Result<CalibratedMix, MixError> {
    let mut mix = PairMix::build(
        spec.profile,
        spec.model,
        spec.iso,
        spec.iso_range,
        spec.ratio,
        spec.darktable,
    )
    .map_err(MixError::Profile)?;
    mix.set_calibrated_dark_level(spec.calibrated_dark_level);
    mix.set_calibrated_share(spec.calibrated_share);
    let mut calibration = None;
    if let Some(path) = spec.calibration {
        let described = mix.describe();
        let Some(one) = mix.single_mut() else {
            return Err(MixError::CalibrationWithMix {
                path: path.to_path_buf(),
                mix: described,
            });
        };
        let cal = CalibrationFile::load(path, None, None)?;
        apply_calibration(Some(&cal), spec.noise_bank, one)?;
        calibration = Some(cal.calibration.identity(path));
    } else if spec.noise_bank {
        return Err(MixError::NoBank { path: None });
    }
    Ok(CalibratedMix { mix, calibration })
}

/// Apply calibration `cal` (its maps, gain and row noise) to `spec` and,
/// with `noise_bank`, its noise bank; a noise bank without a calibration
/// is refused.
pub fn apply_calibration(
    cal: Option<&CalibrationFile>,
    noise_bank: bool,
    spec: &mut PairSpec,
) -> Result<(), MixError> {
    let Some(cal) = cal else {
        return match noise_bank {
            true => Err(MixError::NoBank { path: None }),
            false => Ok(()),
        };
    };
    cal.apply_to(spec)?;
    if noise_bank {
        spec.bank = Some(std::sync::Arc::new(cal.noise_bank()?));
    }
    Ok(())
}

/// The frame a calibration must fit (`pgrf synth`: the clean frame whose
/// pairs it makes), and whether another camera's or ISO's is taken anyway.
#[derive(Clone, Copy)]
pub struct FrameCheck<'a> {
    /// The frame.
    pub frame: &'a RawFrame,
    /// Apply a calibration of another camera or ISO anyway.
    pub force: bool,
}

/// A calibration file as loaded, with its path (for messages).
#[derive(Clone, Debug)]
pub struct CalibrationFile {
    /// Where it was read from.
    pub path: PathBuf,
    /// What it holds.
    pub calibration: Calibration,
}

impl CalibrationFile {
    /// Load the calibration file `path`; with `check`, refuse one of
    /// another camera, of another ISO than `iso` (the capture's), or of
    /// another CFA layout or size than the frame.
    pub fn load(
        path: &Path,
        check: Option<FrameCheck>,
        iso: Option<u32>,
    ) -> Result<CalibrationFile, MixError> {
        let cal = Calibration::load(path).map_err(|e| MixError::Load(Box::new(e)))?;
        if let Some(FrameCheck { frame, force }) = check {
            let mismatch = |source| MixError::Mismatch {
                path: path.to_path_buf(),
                cause: Box::new(source),
            };
            cal.check_matches(&frame.make, &frame.model, iso, force)
                .and_then(|()| cal.check_layout(frame))
                .map_err(mismatch)?;
            let (ph, pw) = frame.packed_dims();
            if (cal.meta.height / 2, cal.meta.width / 2) != (ph, pw) {
                return Err(MixError::Size {
                    path: path.to_path_buf(),
                    calibration: (cal.meta.width, cal.meta.height),
                    frame: (frame.width, frame.height),
                });
            }
        }
        Ok(CalibrationFile {
            path: path.to_path_buf(),
            calibration: cal,
        })
    }

    /// Its noise bank, or why it has none.
    pub fn noise_bank(&self) -> Result<pgrf_noise::bank::NoiseBank, MixError> {
        match self.calibration.bank() {
            Some(Ok(b)) => Ok(b),
            Some(Err(error)) => Err(MixError::Apply {
                path: self.path.clone(),
                cause: Box::new(CalibError::MapValues {
                    path: self.path.clone(),
                    error,
                }),
            }),
            None => Err(MixError::NoBank {
                path: Some(self.path.clone()),
            }),
        }
    }

    /// Apply its maps, gain and row noise to `spec`.
    pub fn apply_to(&self, spec: &mut PairSpec) -> Result<(), MixError> {
        self.calibration
            .apply_to(spec)
            .map_err(|source| MixError::Apply {
                path: self.path.clone(),
                cause: Box::new(source),
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The line a one-line report prints: the error, then each source.
    fn chain(e: &dyn std::error::Error) -> String {
        let mut s = e.to_string();
        let mut next = e.source();
        while let Some(c) = next {
            s.push_str(": ");
            s.push_str(&c.to_string());
            next = c.source();
        }
        s
    }

    /// What a calibration mismatch says appears once in the printed chain
    /// (issue 37: `--calib` errors were printed twice in one line).
    #[test]
    fn a_mismatch_is_said_once() {
        let cause = || {
            Box::new(CalibError::BadOption {
                flag: "--calib",
                message: "calibrated at ISO 800, the frame is ISO 1600".into(),
            })
        };
        let path = PathBuf::from("c.safetensors");
        for e in [
            MixError::Mismatch {
                path: path.clone(),
                cause: cause(),
            },
            MixError::Apply {
                path: path.clone(),
                cause: cause(),
            },
        ] {
            let line = chain(&e);
            assert_eq!(line.matches("ISO 800").count(), 1, "{line}");
            assert!(
                line.contains("c.safetensors: calibrated at ISO 800"),
                "{line}"
            );
        }
    }
}
