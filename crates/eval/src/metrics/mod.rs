//! PSNR, SSIM and ELD's illuminance correction on packed `(C, H, W)` images.
//!
//! One concept per file:
//! - [`psnr`](mod@psnr): peak signal-to-noise ratio, as `skimage.metrics.peak_signal_noise_ratio`.
//! - [`ssim`](mod@ssim): structural similarity, as `skimage.metrics.structural_similarity`
//!   with its defaults (7x7 uniform window, sample covariance, channel mean).
//! - [`cast`]: the colour-cast figure, a mean CIELAB chroma shift over
//!   low-texture blocks (not part of ELD's protocol; pgrf's synthetic one).
//! - `black`: the black-level figures, the mean and median restoration error
//!   where the reference is black (pgrf's synthetic protocol; issue 36).
//! - [`artefacts`]: speckles in flat regions and seams at tile or window
//!   borders, the artefacts of issue 51 item 6.
//! - [`correct`]: ELD's single least-squares brightness gain over unsaturated pixels.
//! - [`protocol`]: the evaluation protocol that strings them together (clamp,
//!   optional correction, x255 as floats) and says in one line what it measured.
//!
//! All accumulation is f64 and every parallel reduction adds its partial sums
//! in a fixed order, so a result does not depend on the number of threads.

pub mod artefacts;
mod black;
pub mod cast;
mod correct;
mod error;
mod input;
mod protocol;
mod psnr;
mod ssim;
mod sum;

pub use artefacts::{seams, speckles, Seams, Speckles};
pub use black::{black_level, BlackLevel};
pub use cast::{colour_cast, CameraColour, Cast};
pub use correct::{illuminance_correct, illuminance_gain, IlluminanceGain};
pub use error::MetricError;
pub use protocol::{evaluate, Protocol, Scores};
pub use psnr::psnr;
pub use ssim::{ssim, SsimOptions};

/// Result type of the metric functions.
pub(crate) type Result<T> = std::result::Result<T, MetricError>;
