//! Restoring a packed array rather than a file: what the Python package's
//! `pgrf.Model.restore` runs. The same steps as `pgrf enhance` after it has
//! decoded a file ([`crate::enhance::enhance_file`]): the normalised
//! capture multiplied by the exposure ratio and clipped at 1
//! ([`pgrf_nn::infer::prepare::amplify`]), the noise level a noise-aware
//! network is told, and the tiled restoration
//! ([`pgrf_nn::infer::restore_packed`]), so an array read from a file gives
//! the pixels `pgrf enhance` writes for it.

use ndarray::Array3;
use pgrf_core::NoProgress;
use pgrf_nn::condition::NoiseLevel;
use pgrf_nn::infer::prepare::amplify;
use pgrf_nn::infer::{restore_packed, Restore, Tiling};
use pgrf_nn::NnError;
use pgrf_noise::lookup::{find_noise, range_of, FrameNoise, KnownNoise};
use pgrf_noise::NoiseError;
use pgrf_raw::RawFrame;

/// Why an array could not be restored.
#[derive(Debug, thiserror::Error)]
pub enum ArrayError {
    /// The array is not packed planes `(4, h, w)` with pixels.
    #[error("packed: expected shape (4, H/2, W/2), got {0:?}")]
    Shape(Vec<usize>),
    /// The array holds NaN or infinite values.
    #[error("packed: {0} values are not finite numbers")]
    NotFinite(usize),
    /// A noise-aware network was given no noise level.
    #[error("{0} is noise-aware: give the capture's noise (S, O) or its metadata to look it up")]
    NoNoise(String),
    /// The noise level given cannot condition a network.
    #[error("noise (S {s}, O {o}): S must be positive and O not negative, both finite")]
    BadNoise {
        /// Signal-dependent variance per unit of normalised signal.
        s: f64,
        /// Signal-independent variance.
        o: f64,
    },
    /// The frame's noise parameters could not be found.
    #[error("noise parameters: {0}")]
    Lookup(#[from] NoiseError),
    /// The ratio, the tiles or the network refused.
    #[error(transparent)]
    Network(#[from] NnError),
}

/// Where a noise-aware network's level comes from.
pub enum ArrayNoise<'a> {
    /// None given (fine for a network that is not told its noise).
    Unknown,
    /// Variance S x + O of the normalised capture at signal x (DNG
    /// NoiseProfile's convention), before the ratio.
    Profile {
        /// S.
        s: f64,
        /// O.
        o: f64,
    },
    /// Found for this frame as `pgrf enhance` finds it without a
    /// calibration or `--noise` (the DNG NoiseProfile, darktable's or a
    /// built-in profile, else the blind estimate on its pixels).
    Lookup(&'a RawFrame),
}

/// The level a network is told for a capture with `noise` on `frame`'s
/// scale, amplified by `ratio` (the one conversion `pgrf enhance` makes).
pub fn level_of(noise: &FrameNoise, frame: &RawFrame, ratio: f32) -> NoiseLevel {
    NoiseLevel::from_dn(
        noise.k,
        noise.read,
        noise.row,
        range_of(frame),
        ratio as f64,
    )
}

/// The noise level `r` is told for a capture amplified by `ratio` (None
/// when `r` is not told one), and what was found when it was looked up.
pub fn array_level(
    r: &dyn Restore,
    noise: ArrayNoise<'_>,
    ratio: f32,
) -> Result<(Option<NoiseLevel>, Option<FrameNoise>), ArrayError> {
    if !r.meta().arch.conditioning().needs_level() {
        return Ok((None, None));
    }
    match noise {
        ArrayNoise::Unknown => Err(ArrayError::NoNoise(r.meta().arch.describe())),
        ArrayNoise::Profile { s, o } => {
            if !(s.is_finite() && o.is_finite() && s > 0.0 && o >= 0.0) {
                return Err(ArrayError::BadNoise { s, o });
            }
            Ok((Some(NoiseLevel::from_normalised(s, o, ratio as f64)), None))
        }
        ArrayNoise::Lookup(frame) => {
            let found = find_noise(frame, &KnownNoise::default())?;
            Ok((Some(level_of(&found, frame, ratio)), Some(found)))
        }
    }
}

/// Restore `packed`, a normalised dark capture `(4, h, w)` (values below
/// black kept), brightened by `ratio`, with `r` told `level`, tiled as
/// `tiling` says: the restored planes in [0, 1], shaped like `packed`.
pub fn restore_array(
    r: &dyn Restore,
    packed: Array3<f32>,
    ratio: f32,
    level: Option<NoiseLevel>,
    tiling: &Tiling,
) -> Result<Array3<f32>, ArrayError> {
    let dims = packed.shape().to_vec();
    if dims[0] != 4 || dims[1] == 0 || dims[2] == 0 {
        return Err(ArrayError::Shape(dims));
    }
    let bad = packed.iter().filter(|v| !v.is_finite()).count();
    if bad > 0 {
        return Err(ArrayError::NotFinite(bad));
    }
    if r.meta().arch.conditioning().needs_level() && level.is_none() {
        return Err(ArrayError::NoNoise(r.meta().arch.describe()));
    }
    let input = amplify(packed, ratio)?;
    Ok(restore_packed(r, input.view(), level, tiling, &NoProgress)?.output)
}
