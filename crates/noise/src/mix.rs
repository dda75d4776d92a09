//! Several cameras' noise in one training set: a weighted mix of
//! [`PairSpec`]s, one drawn per capture.
//!
//! A model trained on one camera's noise learns that camera's read-noise
//! shape, row noise and colour bias; photographers bring other cameras. The
//! mix is written `NAME[@WEIGHT],NAME[@WEIGHT],...` (built-in profile names
//! or JSON paths, weights positive, default 1), e.g.
//! `sony-a7s2@3,nikon-d850@1`.
//!
//! ISO settings are the first profile's. A fixed ISO or an ISO range becomes
//! a range of system gain K (DN per electron) through that profile, and the
//! other profiles draw K from the same range, clipped to the range each was
//! calibrated over. Every profile's DN refer to a ~14-bit white - black
//! scale, so equal K means equal shot noise relative to white: the mix keeps
//! the brightness conditions and varies what differs between sensors (read
//! noise distribution, row noise, colour bias).

use crate::error::{NoiseError, Result};
use crate::model::ModelKind;
use crate::pair::{PairSpec, RatioSpec};
use crate::profile::CameraProfile;
use pgrf_core::seed::mix64;
use pgrf_core::weighted::{parse_weighted, WeightedError};

/// Domain constant of the per-capture profile choice ("prof").
const PICK_DOMAIN: u64 = 0x7072_6f66;

/// One entry of a profile list.
#[derive(Clone, Debug, PartialEq)]
pub struct ProfileEntry {
    /// Built-in name or JSON path.
    pub name: String,
    /// Relative weight (positive).
    pub weight: f64,
}

/// Parse `NAME[@WEIGHT],...`; refuses empty entries and weights that are
/// not positive numbers.
pub fn parse_profiles(text: &str) -> Result<Vec<ProfileEntry>> {
    let bad = |reason: String| NoiseError::ProfileList {
        list: text.into(),
        reason,
    };
    let entries = parse_weighted(text).map_err(|e| {
        bad(match e {
            WeightedError::Empty => {
                "an empty entry (entries are NAME[@WEIGHT], comma-separated)".into()
            }
            WeightedError::BadWeight(item) => {
                format!("{item:?}: the weight after @ must be a positive number")
            }
        })
    })?;
    entries
        .into_iter()
        .map(|(name, weight)| {
            if name.is_empty() {
                return Err(bad(format!(
                    "an entry of weight {weight} has no profile name before @"
                )));
            }
            Ok(ProfileEntry {
                name: name.to_string(),
                weight,
            })
        })
        .collect()
}

/// The noise of one or several cameras, each capture drawing one of them.
#[derive(Clone, Debug)]
pub struct PairMix {
    specs: Vec<PairSpec>,
    /// Cumulative weights normalised to end at 1.
    cumulative: Vec<f64>,
}

impl From<PairSpec> for PairMix {
    fn from(spec: PairSpec) -> PairMix {
        PairMix {
            specs: vec![spec],
            cumulative: vec![1.0],
        }
    }
}

impl PairMix {
    /// The mix of `profiles` (see the module documentation) for noise model
    /// `kind`, ISO settings of the first profile, and `ratio` for all.
    /// Loads and checks every profile and the ISO settings before returning;
    /// `darktable` names darktable's file for `darktable:` profiles.
    pub fn build(
        profiles: &str,
        kind: ModelKind,
        iso: Option<u32>,
        iso_range: Option<(u32, u32)>,
        ratio: RatioSpec,
        darktable: Option<&std::path::Path>,
    ) -> Result<PairMix> {
        let entries = parse_profiles(profiles)?;
        let mut specs = Vec::with_capacity(entries.len());
        let mut gains = None;
        for (i, e) in entries.iter().enumerate() {
            let mut spec = PairSpec::new(CameraProfile::load(&e.name, darktable)?, kind);
            spec.ratio = ratio;
            if i == 0 {
                spec.iso = iso;
                spec.iso_range = iso_range;
                gains = match (iso, iso_range) {
                    (Some(v), _) => {
                        let k = spec.profile.params_at_iso(v)?.k;
                        Some((k, k))
                    }
                    (None, Some((lo, hi))) => Some(spec.k_range(lo, hi)?),
                    (None, None) => None,
                };
            } else if let Some((lo, hi)) = gains {
                let (kmin, kmax) = spec.profile.gain_limits();
                let (a, b) = (lo.clamp(kmin, kmax), hi.clamp(kmin, kmax));
                spec.gain_range = Some((a, b));
            }
            specs.push(spec);
        }
        let total: f64 = entries.iter().map(|e| e.weight).sum();
        let mut acc = 0.0;
        let cumulative = entries
            .iter()
            .map(|e| {
                acc += e.weight / total;
                acc
            })
            .collect();
        Ok(PairMix { specs, cumulative })
    }

    /// The spec capture `seed` uses. A single-profile mix never draws, so
    /// its captures are exactly those of its one [`PairSpec`].
    pub fn pick(&self, seed: u64) -> &PairSpec {
        if self.specs.len() == 1 {
            return &self.specs[0];
        }
        let u = (mix64(seed ^ PICK_DOMAIN) >> 11) as f64 / (1u64 << 53) as f64;
        let i = self
            .cumulative
            .iter()
            .position(|&c| u < c)
            .unwrap_or(self.specs.len() - 1);
        &self.specs[i]
    }

    /// The specs, in the order given.
    pub fn specs(&self) -> &[PairSpec] {
        &self.specs
    }

    /// The single spec, to change (e.g. to apply a calibration); None for a
    /// mix of several cameras, whose captures no one calibration describes.
    pub fn single_mut(&mut self) -> Option<&mut PairSpec> {
        match self.specs.as_mut_slice() {
            [one] => Some(one),
            _ => None,
        }
    }

    /// Every camera's captures without their dark-level offset
    /// ([`PairSpec::calibrated_dark_level`]).
    pub fn set_calibrated_dark_level(&mut self, on: bool) {
        for s in &mut self.specs {
            s.calibrated_dark_level = on;
        }
    }

    /// Every camera's share of captures drawn as calibrated
    /// ([`PairSpec::calibrated_share`]).
    pub fn set_calibrated_share(&mut self, share: f64) {
        for s in &mut self.specs {
            s.calibrated_share = share;
        }
    }

    /// "sony-a7s2" or "sony-a7s2 (75%) + nikon-d850 (25%)", for headers.
    pub fn describe(&self) -> String {
        if self.specs.len() == 1 {
            return self.specs[0].profile.name.clone();
        }
        let mut last = 0.0;
        self.specs
            .iter()
            .zip(&self.cumulative)
            .map(|(s, &c)| {
                let share = c - last;
                last = c;
                format!("{} ({:.0}%)", s.profile.name, 100.0 * share)
            })
            .collect::<Vec<_>>()
            .join(" + ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    fn build(text: &str, range: Option<(u32, u32)>) -> Result<PairMix> {
        PairMix::build(
            text,
            ModelKind::Pgrf,
            None,
            range,
            RatioSpec::Uniform {
                lo: 50.0,
                hi: 100.0,
            },
            None,
        )
    }

    #[test]
    fn parses_names_and_weights_and_refuses_bad_entries() {
        let e = parse_profiles("sony-a7s2@3, nikon-d850").unwrap();
        assert_eq!(e.len(), 2);
        assert_eq!((e[0].name.as_str(), e[0].weight), ("sony-a7s2", 3.0));
        assert_eq!((e[1].name.as_str(), e[1].weight), ("nikon-d850", 1.0));
        for bad in ["", "sony-a7s2,", "a@0", "a@-1", "a@x", "@2", "a@nan"] {
            assert!(parse_profiles(bad).is_err(), "{bad:?} accepted");
        }
        assert!(build("sony-a7s2,no-such-camera", None).is_err());
    }

    #[test]
    fn picks_follow_the_weights_and_repeat_per_seed() {
        let mix = build("sony-a7s2@3,nikon-d850@1", Some((400, 12800))).unwrap();
        assert_eq!(mix.describe(), "sony-a7s2 (75%) + nikon-d850 (25%)");
        let n = 20_000u64;
        let d850 = (0..n)
            .filter(|&s| mix.pick(s).profile.name == "nikon-d850")
            .count() as f64;
        // Binomial(20000, 0.25): sd 61 captures; 5 sd is 0.015.
        assert!(
            (d850 / n as f64 - 0.25).abs() < 0.015,
            "share {}",
            d850 / n as f64
        );
        assert!((0..100).all(|s| std::ptr::eq(mix.pick(s), mix.pick(s))));
    }

    #[test]
    fn the_first_profiles_iso_range_becomes_everyones_gain_range() {
        let mix = build("sony-a7s2,nikon-d850", Some((800, 3200))).unwrap();
        let a7s2 = &mix.specs()[0];
        let (lo, hi) = a7s2.k_range(800, 3200).unwrap();
        // The A7S2's K is 9.563e-4 x ISO.
        assert!((lo - 0.76504).abs() < 1e-4 && (hi - 3.06016).abs() < 1e-4);
        let d850 = &mix.specs()[1];
        assert_eq!(d850.gain_range, Some((lo, hi)));
        // Its captures' K stay inside the range.
        let clean = Array3::<f32>::from_elem((4, 8, 8), 0.2);
        for seed in 0..50 {
            let p = d850.synthesize(clean.view(), [0, 0, 1, 1], seed).unwrap();
            assert!(
                p.params.k >= lo - 1e-12 && p.params.k <= hi + 1e-12,
                "K {}",
                p.params.k
            );
        }
        // A single profile is the plain spec: no gain range, no draw.
        let one = build("nikon-d850", None).unwrap();
        assert_eq!(one.specs()[0].gain_range, None);
        assert_eq!(one.describe(), "nikon-d850");
    }

    #[test]
    fn gain_ranges_are_clipped_to_what_a_profile_was_calibrated_over() {
        // ISO 12800 on the A7S2 is K 12.2, above its own calibrated 6.0 but
        // inside the D850's 0.42..26.6; ISO 400 is K 0.38, below the D850's.
        let mix = build("sony-a7s2,nikon-d850", Some((400, 12800))).unwrap();
        let (lo, hi) = mix.specs()[1].gain_range.unwrap();
        assert!((lo - 0.415039).abs() < 1e-5, "lo {lo}");
        assert!((hi - 12.2406).abs() < 1e-3, "hi {hi}");
    }
}
