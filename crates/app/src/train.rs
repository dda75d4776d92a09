//! `pgrf train`'s recipe: `pgrf_nn::train::run` with the pairs' noise built
//! from the configuration's profiles and the calibration `--calib` names
//! (`pgrf_calib::mix`), which the network crate does not depend on.

use pgrf_calib::mix::{MixError, MixSpec};
use pgrf_core::Progress;
use pgrf_nn::train::{PairsNoise, Trained};
use pgrf_nn::{Method, NnError, Result, TrainConfig};
use std::sync::atomic::AtomicBool;

/// Train `method`'s network as `config` says ([`pgrf_nn::train::run`], whose
/// documentation says what is checked first and what `progress`, `stop` and
/// `warn` hear), its pairs' noise from [`pairs_noise`].
pub fn run(
    config: &TrainConfig,
    method: Method,
    resume: bool,
    progress: &dyn Progress,
    stop: &AtomicBool,
    warn: &dyn Fn(&str),
) -> Result<Trained> {
    pgrf_nn::train::run(config, method, resume, &pairs_noise, progress, stop, warn)
}

/// The pairs' noise: the profiles (or mix) and the calibration, with the
/// errors named by the flags that set them.
pub fn pairs_noise(c: &TrainConfig, iso_range: Option<(u32, u32)>) -> Result<PairsNoise> {
    let built = pgrf_calib::mix::build(&MixSpec {
        profile: &c.profile,
        model: c.noise,
        iso: c.iso,
        iso_range,
        ratio: c.ratio_draw.spec(c.ratio_min, c.ratio_max),
        calibrated_dark_level: c.calibrated_dark_level,
        calibrated_share: c.calibrated_share,
        calibration: c.calib.as_deref(),
        noise_bank: c.noise_bank,
        darktable: c.darktable_profiles.as_deref(),
    })
    .map_err(|e| match e {
        MixError::Profile(e) => NnError::BadSetting {
            flag: "--profile",
            message: format!("--profile: {e}"),
        },
        MixError::CalibrationWithMix { path, mix } => NnError::BadSetting {
            flag: "--calib",
            message: format!(
                "--calib {} describes one sensor; it cannot go with a mix of profiles ({mix})",
                path.display()
            ),
        },
        e => NnError::Caller(Box::new(e)),
    })?;
    Ok(PairsNoise {
        mix: built.mix,
        calibration: built.calibration,
    })
}
