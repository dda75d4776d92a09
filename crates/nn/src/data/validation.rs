//! Held-out validation pairs: made once, from a seed disjoint from the
//! training stream, so the PSNR printed every N steps is measured on the
//! same images throughout the run (and after a resume).

use crate::condition::NoiseLevel;
use crate::data::loader::{make_sample, Extras, SampleSpec};
use crate::data::source::Source;
use crate::error::Result;
use pgrf_core::seed::mix64;
use pgrf_noise::mix::PairMix;

const VAL_DOMAIN: u64 = 0x7661_6c69; // "vali"

/// One validation pair (each `(4, P, P)` packed R, G1, B, G2, flattened in
/// row-major order) with its flow start X0.
#[derive(Clone, Debug)]
pub struct ValPair {
    /// The network input T: the synthetic noisy crop amplified by `ratio`,
    /// clamped to [0, 1].
    pub noisy: Vec<f32>,
    /// The clean target X1 in [0, 1].
    pub clean: Vec<f32>,
    /// The flow model's start X0 ~ N(0, I) for this pair (the denoiser
    /// ignores it).
    pub x0: Vec<f32>,
    /// The exposure ratio the pair was synthesised at.
    pub ratio: f32,
    /// The noise level of `noisy` (what a conditioned network is told).
    pub level: NoiseLevel,
}

/// The held-out pairs a run (or the sampling search) is scored on, all of
/// one crop size.
#[derive(Clone, Debug)]
pub struct ValSet {
    /// Side P of every crop, in packed pixels.
    pub patch: usize,
    /// The pairs, in a fixed order.
    pub pairs: Vec<ValPair>,
}

impl ValSet {
    /// Bytes `count` pairs of `patch` x `patch` packed crops hold: the
    /// noisy input, the clean target and the start field, four planes of
    /// f32 each; checked against the memory there is before they are made.
    pub fn bytes(patch: usize, count: usize) -> f64 {
        count as f64 * 3.0 * 4.0 * (patch * patch) as f64 * 4.0
    }

    /// `count` pairs of `patch` x `patch` crops from `source`, noise from
    /// `mix`, no augmentation: pair i is a function of (`seed`, i) only,
    /// drawn from streams apart from the training samples of the same seed.
    pub fn build(
        source: &Source,
        mix: &PairMix,
        patch: usize,
        count: usize,
        seed: u64,
    ) -> Result<ValSet> {
        let s = SampleSpec {
            patch,
            seed: mix64(seed ^ VAL_DOMAIN),
            augment: false,
            extras: Extras::Flow { t_max: 1.0 },
        };
        let pairs = (0..count as u64)
            .map(|i| {
                let item = make_sample(source, mix, &s, i)?;
                Ok(ValPair {
                    noisy: item.noisy,
                    clean: item.clean,
                    x0: item.x0,
                    ratio: item.ratio,
                    level: item.level,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(ValSet { patch, pairs })
    }
}

/// PSNR (dB) of `a` against reference `b` on [0, 1] data (a clamped first),
/// peak 1, over every element; capped at 200 dB for identical inputs. The
/// quick score of training logs (ELD's protocol is pgrf-eval's).
pub fn psnr(a: &[f32], b: &[f32]) -> f32 {
    let mse = a
        .iter()
        .zip(b)
        .map(|(x, y)| {
            let d = x.clamp(0.0, 1.0) as f64 - *y as f64;
            d * d
        })
        .sum::<f64>()
        / a.len().max(1) as f64;
    (10.0 * (1.0 / mse.max(1e-20)).log10()) as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use pgrf_noise::{CameraProfile, ModelKind};

    #[test]
    fn psnr_of_a_known_error() {
        // Constant error 0.01 -> MSE 1e-4 -> 40 dB; values above 1 are clamped.
        let b = vec![0.5f32; 100];
        let a = vec![0.51f32; 100];
        assert!((psnr(&a, &b) - 40.0).abs() < 1e-3);
        assert!((psnr(&[2.0], &[0.9]) - 20.0).abs() < 1e-3);
    }

    #[test]
    fn the_validation_set_is_fixed_and_differs_from_training() {
        let mut spec = pgrf_noise::pair::PairSpec::new(
            CameraProfile::built_in("sony-a7s2").unwrap(),
            ModelKind::Eld,
        );
        spec.iso = Some(3200);
        let spec = PairMix::from(spec);
        let a = ValSet::build(&Source::Procedural, &spec, 32, 2, 1).unwrap();
        let b = ValSet::build(&Source::Procedural, &spec, 32, 2, 1).unwrap();
        assert_eq!(a.pairs[1].noisy, b.pairs[1].noisy);
        let train = SampleSpec {
            patch: 32,
            seed: 1,
            augment: false,
            extras: Extras::None,
        };
        let t = make_sample(&Source::Procedural, &spec, &train, 0).unwrap();
        assert_ne!(t.clean, a.pairs[0].clean);
        // The noisy input is far from the clean target: there is work to do.
        assert!(psnr(&a.pairs[0].noisy, &a.pairs[0].clean) < 35.0);
    }
}
