//! Noise conditioning: telling a network how noisy its input is, so that one
//! network serves every camera, ISO and exposure ratio instead of guessing
//! the level from the pixels (and smoothing away detail where the noise is
//! low).
//!
//! The noise of an amplified, normalised input x (the network's input: a
//! capture divided by its white - black, times the exposure ratio r) is
//! signal-dependent: Var(x) = gain * E\[x\] + floor, with gain = r K / range
//! (K in DN per electron) and floor = r^2 (sigma_read^2 + sigma_row^2) /
//! range^2 ([`NoiseLevel`]). Two ways of giving it to a network
//! ([`Conditioning`]):
//!
//! - **sigma map** (FFDNet; Ansel's sigma-map U-Net): four more input
//!   planes holding sqrt(gain * x + floor), the standard deviation the level
//!   predicts at each packed pixel (from the clamped input itself);
//! - **log-sigma map**: the same four planes as (ln sigma - [`LOG_SIGMA_CENTRE`])
//!   / [`LOG_SIGMA_SPREAD`]. The deviations of interest span two decades
//!   (0.003 at a camera's own low-ISO noise to 0.3 at ISO 12800 x200); as
//!   raw values they reach the first layer 10-100x weaker than the image
//!   planes, and a network started from blind weights (zero plane weights)
//!   learnt little use of them in 7,000 steps (MODELS.md). In the log they
//!   span about -1.2..1.2, the image planes' scale, and equal steps in noise
//!   ratio are equal steps in the input;
//! - **k-sigma** (Wang et al., "Practical Deep Raw Image Denoising on Mobile
//!   Devices", ECCV 2020): the input mapped by x' = x g/gain + g floor/gain^2
//!   (g = [`KSIGMA_REF_GAIN`]), in which the noise is Poisson-like with the
//!   fixed gain g whatever the camera, ISO or ratio (Var(x') = g E\[x'\]); the
//!   network works in that domain and its output is mapped back.
//!
//! Both are per-pixel, so a conditioned network stays independent of how a
//! frame is tiled. Unconditioned networks ([`Conditioning::None`], every
//! file written before conditioning existed) run exactly as before.

use burn::tensor::backend::Backend;
use burn::tensor::{Tensor, TensorData};
use serde::{Deserialize, Serialize};

/// The fixed gain of the k-sigma domain: about the A7S2's at ISO 1600 and
/// x100 (1.53 DN/e- x 100 / 15871 DN), so that mid-range training captures
/// keep roughly their scale.
pub const KSIGMA_REF_GAIN: f32 = 0.01;

/// The smallest gain a level may have: below it the k-sigma domain's scale
/// (`KSIGMA_REF_GAIN / gain`) exceeds 10^6 and f32 loses the image.
const MIN_GAIN: f32 = pgrf_noise::lookup::MIN_SIGNAL_GAIN as f32;

/// The log-sigma planes are (ln sigma - centre) / spread: sigma 0.03 (ln
/// -3.5, mid-range training noise) maps to 0.
pub const LOG_SIGMA_CENTRE: f32 = -3.5;

/// See [`LOG_SIGMA_CENTRE`]: sigma 0.003 maps to -1.15, sigma 0.3 to +1.15.
pub const LOG_SIGMA_SPREAD: f32 = 2.0;

/// The smallest deviation the log-sigma planes hold (a noiseless black
/// pixel would be ln 0): 1e-4 of white, a tenth of a 14-bit camera's read
/// noise at its lowest ISO.
const MIN_LOG_SIGMA: f32 = 1e-4;

/// The noise of an amplified, normalised network input: Var(x) = gain *
/// E\[x\] + floor, in the input's units.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct NoiseLevel {
    /// Signal-dependent part: the variance per unit of signal (r K / range).
    pub gain: f32,
    /// Signal-independent part: read and row noise variance (r^2 sigma^2 /
    /// range^2).
    pub floor: f32,
}

impl NoiseLevel {
    /// The level of a capture with system gain `k` (DN per electron), read
    /// noise `read` and row noise `row` (standard deviations, DN), normalised
    /// by `range` (white - black, DN) and amplified by `ratio`.
    pub fn from_dn(k: f64, read: f64, row: f64, range: f64, ratio: f64) -> NoiseLevel {
        NoiseLevel {
            gain: (ratio * k / range) as f32,
            floor: (ratio * ratio * (read * read + row * row) / (range * range)) as f32,
        }
    }

    /// The level of a normalised capture whose variance is `s` x + `o` at
    /// signal x (the DNG NoiseProfile's convention, on the scale (DN -
    /// black) / (white - black)), amplified by `ratio`.
    pub fn from_normalised(s: f64, o: f64, ratio: f64) -> NoiseLevel {
        NoiseLevel {
            gain: (ratio * s) as f32,
            floor: (ratio * ratio * o) as f32,
        }
    }

    /// Whether both parts are finite, the gain positive and the floor not
    /// negative: what a network can be conditioned on.
    pub fn is_usable(&self) -> bool {
        self.gain.is_finite()
            && self.floor.is_finite()
            && self.gain >= MIN_GAIN
            && self.floor >= 0.0
    }

    /// The standard deviation the level predicts at signal `x` (negative
    /// signal counts as none).
    pub fn sigma_at(&self, x: f32) -> f32 {
        (self.gain * x.max(0.0) + self.floor).sqrt()
    }

    /// The k-sigma map x -> x * scale + offset as (scale, offset).
    pub fn ksigma(&self) -> (f32, f32) {
        let scale = KSIGMA_REF_GAIN / self.gain;
        (scale, self.floor * scale / self.gain)
    }
}

/// How a network is told the noise level of its input; recorded in the
/// network's configuration (`"conditioning"`, absent = none).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Conditioning {
    /// Not told: the network infers the level from the pixels (every file
    /// written before conditioning existed).
    #[default]
    None,
    /// Four more input planes: the noise standard deviation at each packed
    /// pixel.
    SigmaMap,
    /// The input in the k-sigma domain, the output mapped back.
    KSigma,
    /// Four more input planes: the log of the noise standard deviation at
    /// each packed pixel, centred and scaled to the image planes' range.
    LogSigmaMap,
}

impl Conditioning {
    /// Input planes a network adds for the conditioning (the four packed
    /// planes come first).
    pub fn extra_channels(self) -> usize {
        match self {
            Conditioning::SigmaMap | Conditioning::LogSigmaMap => 4,
            Conditioning::None | Conditioning::KSigma => 0,
        }
    }

    /// Whether the network needs a noise level to run.
    pub fn needs_level(self) -> bool {
        self != Conditioning::None
    }

    /// The name in records and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Conditioning::None => "none",
            Conditioning::SigmaMap => "sigma-map",
            Conditioning::KSigma => "k-sigma",
            Conditioning::LogSigmaMap => "log-sigma-map",
        }
    }

    /// In words: "unconditioned", "sigma-map conditioned", ...
    pub fn describe(self) -> String {
        match self {
            Conditioning::None => "unconditioned".into(),
            c => format!("{} conditioned", c.name()),
        }
    }

    /// The per-item (scale, offset) of the network's domain: the k-sigma
    /// map, or the identity.
    fn affine(self, level: &NoiseLevel) -> (f32, f32) {
        match self {
            Conditioning::KSigma => level.ksigma(),
            Conditioning::None | Conditioning::SigmaMap | Conditioning::LogSigmaMap => (1.0, 0.0),
        }
    }
}

/// A batch prepared for a conditioned network: its input (in the network's
/// domain, with the sigma planes when there are any) and the per-item map
/// into that domain, to bring outputs back and targets in.
pub struct Conditioned<B: Backend> {
    /// The network's condition, `(n, 4 + extra, h, w)`.
    pub input: Tensor<B, 4>,
    /// Per item, `(n, 1, 1, 1)`: the domain is x * scale + offset.
    scale: Tensor<B, 4>,
    offset: Tensor<B, 4>,
    identity: bool,
}

impl<B: Backend> Conditioned<B> {
    /// `noisy` `(n, 4, h, w)` prepared as `kind` says, item i at `levels[i]`
    /// (ignored, and may be empty, without conditioning).
    pub fn new(kind: Conditioning, noisy: Tensor<B, 4>, levels: &[NoiseLevel]) -> Self {
        let device = noisy.device();
        let n = noisy.dims()[0];
        if kind == Conditioning::None {
            let one = Tensor::ones([n, 1, 1, 1], &device);
            return Conditioned {
                input: noisy,
                scale: one.clone(),
                offset: one.zeros_like(),
                identity: true,
            };
        }
        assert_eq!(levels.len(), n, "one noise level per item");
        let column = |f: &dyn Fn(&NoiseLevel) -> f32| {
            let v: Vec<f32> = levels.iter().map(f).collect();
            Tensor::<B, 4>::from_data(TensorData::new(v, [n, 1, 1, 1]), &device)
        };
        let scale = column(&|l| kind.affine(l).0);
        let offset = column(&|l| kind.affine(l).1);
        let mut input = noisy.clone() * scale.clone() + offset.clone();
        if kind.extra_channels() > 0 {
            let gain = column(&|l| l.gain);
            let floor = column(&|l| l.floor);
            let sigma = (noisy.clamp_min(0.0) * gain + floor).sqrt();
            let planes = match kind {
                Conditioning::LogSigmaMap => {
                    (sigma.clamp_min(MIN_LOG_SIGMA).log() - LOG_SIGMA_CENTRE) / LOG_SIGMA_SPREAD
                }
                _ => sigma,
            };
            input = Tensor::cat(vec![input, planes], 1);
        }
        Conditioned {
            input,
            scale,
            offset,
            identity: kind != Conditioning::KSigma,
        }
    }

    /// `x` (4 planes, input units) in the network's domain.
    pub(crate) fn domain_of(&self, x: Tensor<B, 4>) -> Tensor<B, 4> {
        if self.identity {
            x
        } else {
            x * self.scale.clone() + self.offset.clone()
        }
    }

    /// `y` (4 planes, the network's domain) back in input units.
    pub fn input_units_of(&self, y: Tensor<B, 4>) -> Tensor<B, 4> {
        if self.identity {
            y
        } else {
            (y - self.offset.clone()) / self.scale.clone()
        }
    }

    /// Per item, the factor that brings a difference in the network's
    /// domain back to input units (1 / scale), `(n, 1, 1, 1)`; None for the
    /// identity.
    pub(crate) fn inverse_scale(&self) -> Option<Tensor<B, 4>> {
        (!self.identity).then(|| self.scale.clone().recip())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    type B = crate::backend::Cpu;

    fn batch() -> Tensor<B, 4> {
        let v: Vec<f32> = (0..2 * 4 * 3 * 3)
            .map(|i| (i as f32 * 0.37).sin() * 0.6 + 0.3)
            .collect();
        Tensor::from_data(TensorData::new(v, [2, 4, 3, 3]), &Default::default())
    }

    /// The NoiseProfile pair of a capture (S = K / range, O = (read^2 +
    /// row^2) / range^2) gives the level its DN parameters give: the A7S2 at
    /// ISO 1600 (K 1.5301, read 6.299, row 0.989 DN, range 15871) x100.
    #[test]
    fn the_noise_profile_pair_is_the_dn_parameters_level() {
        let (k, read, row, range, ratio) = (1.5301, 6.299, 0.989, 15871.0, 100.0);
        let dn = NoiseLevel::from_dn(k, read, row, range, ratio);
        let s = k / range;
        let o = (read * read + row * row) / (range * range);
        let pair = NoiseLevel::from_normalised(s, o, ratio);
        assert!(
            (pair.gain - dn.gain).abs() <= 1e-7 * dn.gain,
            "{pair:?} {dn:?}"
        );
        assert!(
            (pair.floor - dn.floor).abs() <= 1e-7 * dn.floor,
            "{pair:?} {dn:?}"
        );
        // 0.00964 and 0.00161: x100 of the A7S2's gain and floor.
        assert!(
            (dn.gain - 0.009641).abs() < 1e-6 && (dn.floor - 1.6140e-3).abs() < 1e-7,
            "{dn:?}"
        );
    }

    fn levels() -> Vec<NoiseLevel> {
        vec![
            NoiseLevel::from_dn(1.53, 3.2, 0.4, 15871.0, 100.0),
            NoiseLevel::from_dn(0.12, 1.1, 0.1, 16383.0, 20.0),
        ]
    }

    #[test]
    fn the_level_of_a_capture_is_its_variance_in_input_units() {
        // A7S2 ISO 1600 at x100: gain 100 * 1.53 / 15871, floor (100 * sqrt(3.2^2 + 0.4^2) / 15871)^2.
        let l = NoiseLevel::from_dn(1.53, 3.2, 0.4, 15871.0, 100.0);
        assert!((l.gain - 9.6402e-3).abs() < 1e-6, "{}", l.gain);
        assert!((l.floor - 4.1289e-4).abs() < 1e-7, "{}", l.floor);
        assert!((l.sigma_at(0.25) - (0.25 * l.gain + l.floor).sqrt()).abs() < 1e-9);
        assert_eq!(l.sigma_at(-1.0), l.floor.sqrt());
        assert!(l.is_usable());
        assert!(!NoiseLevel {
            gain: 0.0,
            floor: 1.0
        }
        .is_usable());
        assert!(!NoiseLevel {
            gain: f32::NAN,
            floor: 1.0
        }
        .is_usable());
    }

    #[test]
    fn the_ksigma_domain_has_the_reference_gain_and_round_trips() {
        for l in levels() {
            let (s, o) = l.ksigma();
            // Var(x s + o) = s^2 (gain x + floor) must equal g (x s + o).
            for x in [0.0f32, 0.1, 0.7] {
                let var = s * s * (l.gain * x + l.floor);
                let want = KSIGMA_REF_GAIN * (x * s + o);
                assert!(
                    (var - want).abs() <= 1e-5 * want.max(1e-6),
                    "{var} vs {want}"
                );
            }
        }
        let x = batch();
        let c = Conditioned::new(Conditioning::KSigma, x.clone(), &levels());
        assert_eq!(c.input.dims(), [2, 4, 3, 3]);
        let back = c.input_units_of(c.domain_of(x.clone()));
        let err = (back - x).abs().max().into_scalar();
        assert!(err < 1e-5, "round trip error {err}");
    }

    #[test]
    fn the_sigma_map_adds_four_planes_of_the_predicted_deviation() {
        let x = batch();
        let ls = levels();
        let c = Conditioned::new(Conditioning::SigmaMap, x.clone(), &ls);
        assert_eq!(c.input.dims(), [2, 8, 3, 3]);
        let got = c.input.clone().into_data().to_vec::<f32>().unwrap();
        let xs = x.clone().into_data().to_vec::<f32>().unwrap();
        for item in 0..2 {
            for k in 0..36 {
                let plane = got[item * 72 + k];
                assert_eq!(
                    plane,
                    xs[item * 36 + k],
                    "the four planes come first, unchanged"
                );
                let sigma = got[item * 72 + 36 + k];
                let want = ls[item].sigma_at(xs[item * 36 + k]);
                assert!((sigma - want).abs() < 1e-6, "{sigma} vs {want}");
            }
        }
        // The identity domain: outputs pass through untouched.
        let y = c.input_units_of(x.clone());
        assert_eq!(y.into_data(), x.into_data());
    }

    /// The log-sigma planes are the log of the sigma planes, centred and
    /// scaled; a noiseless black pixel is held at the smallest deviation.
    #[test]
    fn the_log_sigma_map_is_the_scaled_log_of_the_deviation() {
        let x = batch();
        let ls = levels();
        let plain = Conditioned::new(Conditioning::SigmaMap, x.clone(), &ls);
        let logged = Conditioned::new(Conditioning::LogSigmaMap, x.clone(), &ls);
        assert_eq!(logged.input.dims(), [2, 8, 3, 3]);
        let a = plain.input.into_data().to_vec::<f32>().unwrap();
        let b = logged.input.into_data().to_vec::<f32>().unwrap();
        for item in 0..2 {
            for k in 0..36 {
                let (i, j) = (item * 72 + k, item * 72 + 36 + k);
                assert_eq!(a[i], b[i], "the four planes come first, unchanged");
                let want = (a[j].max(1e-4).ln() + 3.5) / 2.0;
                assert!((b[j] - want).abs() < 1e-5, "{} vs {want}", b[j]);
            }
        }
        // sigma 0.003 and 0.3, the ends of the training range, land at
        // -1.15 and +1.15.
        for (sigma, want) in [(0.003f32, -1.1546), (0.3, 1.1480)] {
            let got = (sigma.ln() - LOG_SIGMA_CENTRE) / LOG_SIGMA_SPREAD;
            assert!((got - want).abs() < 1e-3, "{sigma}: {got}");
        }
        let silent = NoiseLevel {
            gain: 1e-6,
            floor: 0.0,
        };
        let black = Tensor::<B, 4>::zeros([1, 4, 1, 1], &Default::default());
        let c = Conditioned::new(Conditioning::LogSigmaMap, black, &[silent]);
        let v = c.input.into_data().to_vec::<f32>().unwrap();
        let floor = (1e-4f32.ln() + 3.5) / 2.0;
        assert!(v[4..].iter().all(|p| (p - floor).abs() < 1e-5), "{v:?}");
    }

    #[test]
    fn without_conditioning_the_input_is_the_batch_itself() {
        let x = batch();
        let c = Conditioned::new(Conditioning::None, x.clone(), &[]);
        assert!(c.inverse_scale().is_none());
        assert_eq!(c.input.into_data(), x.into_data());
    }
}
