//! The training configuration: every setting of `pgrf train`, with each
//! default stated once (here, or in the network configurations it defers
//! to), read from and written as TOML, and stored in the weight file it
//! produced so that a run can be repeated from its result.
//!
//! Keys are the command-line flags with underscores (`--ratio-min` is
//! `ratio_min`); a file may hold any subset and the flags override it.

use crate::error::{NnError, Result};
use crate::schedule::Schedule;
use crate::sr3::Sr3Config;
use crate::unet::SidUnetConfig;
use crate::weights::Architecture;
use pgrf_noise::ModelKind;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// What `pgrf train` trains: the paper's two methods.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// SPC: the SID U-Net denoiser, L1(denoise(noisy x ratio), clean).
    #[serde(alias = "denoiser")]
    Spc,
    /// PGRF: the SR3 velocity field of the physics-guided rectified flow.
    #[serde(alias = "flow")]
    Pgrf,
}

impl Method {
    /// The name users see ("spc", "pgrf").
    pub fn name(self) -> &'static str {
        match self {
            Method::Spc => "spc",
            Method::Pgrf => "pgrf",
        }
    }
}

impl std::str::FromStr for Method {
    type Err = String;
    /// `spc` or `pgrf`; `denoiser` and `flow` (what they train) also work.
    fn from_str(s: &str) -> std::result::Result<Method, String> {
        match s.to_ascii_lowercase().as_str() {
            "spc" | "denoiser" => Ok(Method::Spc),
            "pgrf" | "flow" => Ok(Method::Pgrf),
            o => Err(format!(
                "unknown method '{o}' (spc or pgrf; denoiser and flow name the same)"
            )),
        }
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Every training setting. `None` means "derived": from the network
/// configuration's own default (`width`, SR3 sizes), from another setting
/// (`val_patch` from `patch`, `checkpoint` and `log` from `output`), or
/// not used (`clip_grad`, `iso`, `calib`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainConfig {
    /// Clean training images: comma-separated entries `SOURCE[@WEIGHT]`,
    /// each a folder (or file) of clean RAWs, a folder of photos (JPEG, PNG,
    /// TIFF), or "procedural"; crops are drawn from the entries in
    /// proportion to their weights (default 1 each). See [`crate::data::build`].
    pub data: String,
    /// Validation images (default: 10% of `data`'s files held out).
    pub val_data: Option<String>,
    /// Camera noise profile, built-in name or JSON path, or a weighted mix
    /// `NAME[@WEIGHT],...` (see `pgrf_noise::mix`).
    pub profile: String,
    /// Per-pixel calibration file for the pgrf noise model.
    pub calib: Option<PathBuf>,
    /// Noise model of the synthetic pairs.
    pub noise: ModelKind,
    /// Fixed ISO (None: parameters drawn from the profile's distribution).
    pub iso: Option<u32>,
    /// Without a fixed ISO: draw the gain between these two ISOs only
    /// (None: the profile's whole range, ELD's distribution).
    pub iso_range: Option<Vec<u32>>,
    /// The camera photos are unprocessed into: any RAW file of it (its
    /// colour matrix, white balance, CFA and levels). None: the built-in
    /// A7S2's with the sony-a7s2 profile; other profiles need one.
    pub camera_like: Option<PathBuf>,
    /// Photos: downscale factor per side before cropping (area filter).
    pub photo_downscale: usize,
    /// Photos: invert a global S-shaped tone curve before the sRGB transfer.
    pub photo_inverse_tone: bool,
    /// Photos: the largest factor (and its inverse the smallest) by which
    /// each crop's red and blue white-balance multipliers are varied,
    /// log-uniform. 1.25 spans daylight, shade and flash on one camera;
    /// wider ranges reach cameras whose raw channels are nearly balanced.
    pub photo_wb_spread: f32,
    /// Smallest exposure ratio (ELD/SID: 100; pgrf's general models: 1).
    pub ratio_min: f32,
    /// Largest exposure ratio (ELD/SID: 300).
    pub ratio_max: f32,
    /// Side of the packed training crops (ELD/SID: 512).
    pub patch: usize,
    /// Crops per step.
    pub batch: usize,
    /// Data worker threads.
    pub workers: usize,
    /// Memory for decoded training RAWs, MiB.
    pub cache_mib: usize,
    /// Optimisation steps.
    pub steps: u64,
    /// Base learning rate (ELD: 1e-4).
    pub lr: f64,
    /// Learning-rate schedule.
    pub schedule: Schedule,
    /// Per-tensor gradient norm limit.
    pub clip_grad: Option<f32>,
    /// Seed of initialisation, crops, noise, X0 and t.
    pub seed: u64,
    /// Turn off flips and transposes.
    pub no_augment: bool,
    /// Train on captures without the camera's dark-level offset (black-level
    /// error, colour bias): for inputs calibrated as `pgrf enhance --calib`
    /// and the synthetic protocol make them. Without it the network learns
    /// to guess an offset it cannot see, and subtracts the average guess
    /// from calibrated inputs too (a tint in dark areas).
    pub calibrated_dark_level: bool,
    /// SID U-Net width; for the flow model the SR3 inner channels unless
    /// `inner_channels` is given.
    pub width: Option<usize>,
    /// Learn a correction to the input (not the papers' design).
    pub residual: bool,
    /// Start from this weight file's weights (a network of exactly this
    /// configuration) instead of fresh ones: fine-tuning a trained model on
    /// other data or conditions. The optimiser and the schedule start
    /// afresh; a resumed run takes its weights from the checkpoint.
    pub init: Option<PathBuf>,
    /// SR3 channels of the first level.
    pub inner_channels: Option<usize>,
    /// SR3 channel multipliers per level.
    pub channel_mults: Option<Vec<usize>>,
    /// SR3 residual blocks per level.
    pub res_blocks: Option<usize>,
    /// SR3 levels with self-attention.
    pub attn_levels: Option<Vec<usize>>,
    /// SR3 GroupNorm groups (None: the largest <= 32 dividing every level).
    pub norm_groups: Option<usize>,
    /// SR3 dropout.
    pub dropout: Option<f64>,
    /// Validate every N steps (0: only at the end).
    pub val_every: u64,
    /// Validation pairs.
    pub val_pairs: usize,
    /// Side of the validation crops (None: min(patch, 256)).
    pub val_patch: Option<usize>,
    /// t2 of the two-stage sampler when validating the flow model.
    pub val_t2: f32,
    /// Flow model: draw the training time t from U(0, time_max) instead of
    /// Algorithm 1's U(0, 1). The two-stage sampler only evaluates t = 0
    /// and t = t2, and the residual field's L1 loss weighs late times up to
    /// ten times more (MODELS.md, "The calibrated measure"); a range
    /// covering t2 spends the training on the times the sampler uses. The
    /// Euler sampler and the search's t above `time_max` leave what the
    /// field learned.
    pub time_max: f32,
    /// Checkpoint every N steps.
    pub checkpoint_every: u64,
    /// Checkpoint file (None: the output with extension .ckpt).
    pub checkpoint: Option<PathBuf>,
    /// Log file, CSV or JSON lines (None: the output with .log.csv).
    pub log: Option<PathBuf>,
    /// Log the mean loss every N steps.
    pub log_every: u64,
    /// Weight file to write.
    pub output: Option<PathBuf>,
    /// cpu or cuda.
    pub device: crate::backend::DeviceKind,
}

impl Default for TrainConfig {
    /// ELD/SID's recipe where it applies (512 crops, Adam at 1e-4 with the
    /// step schedule), the A7S2 profile and pgrf's noise model; exposure
    /// ratios 1..300 (a general model meets bright captures too, not only
    /// ELD's x100..x300).
    fn default() -> Self {
        TrainConfig {
            data: "procedural".into(),
            val_data: None,
            profile: "sony-a7s2".into(),
            calib: None,
            noise: ModelKind::Pgrf,
            iso: None,
            iso_range: None,
            camera_like: None,
            photo_downscale: 2,
            photo_inverse_tone: false,
            photo_wb_spread: crate::data::photos::WB_SPREAD,
            ratio_min: 1.0,
            ratio_max: 300.0,
            patch: 512,
            batch: 1,
            workers: 2,
            cache_mib: 4096,
            steps: 30_000,
            lr: 1e-4,
            schedule: Schedule::Eld,
            clip_grad: None,
            seed: 0,
            no_augment: false,
            calibrated_dark_level: false,
            width: None,
            residual: false,
            init: None,
            inner_channels: None,
            channel_mults: None,
            res_blocks: None,
            attn_levels: None,
            norm_groups: None,
            dropout: None,
            val_every: 1000,
            val_pairs: 4,
            val_patch: None,
            val_t2: 0.5,
            time_max: 1.0,
            checkpoint_every: 1000,
            checkpoint: None,
            log: None,
            log_every: 10,
            output: None,
            device: crate::backend::DeviceKind::Cpu,
        }
    }
}

fn invalid(what: impl std::fmt::Display) -> NnError {
    NnError::Config(what.to_string())
}

impl TrainConfig {
    /// Parse a TOML file's text (any subset of the keys; unknown keys are
    /// refused with their name).
    pub fn from_toml(text: &str) -> Result<TrainConfig> {
        toml::from_str(text).map_err(|e| invalid(e.message()))
    }

    /// The whole configuration as TOML (unset optional keys left out).
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("a TrainConfig always serialises")
    }

    /// This configuration with the keys of `over` (e.g. the flags a user
    /// gave) replacing its own; `over` is checked like a file.
    pub fn overlay<T: Serialize>(&self, over: &T) -> Result<TrainConfig> {
        let mut base = toml::Table::try_from(self).map_err(invalid)?;
        let top = toml::Table::try_from(over).map_err(invalid)?;
        base.extend(top);
        base.try_into::<TrainConfig>()
            .map_err(|e| invalid(e.message()))
    }

    /// The network this configuration trains for `method`, checked.
    pub fn architecture(&self, method: Method) -> Result<Architecture> {
        Ok(match method {
            Method::Spc => {
                let cfg = SidUnetConfig::new().with_residual(self.residual);
                let w = self.width.unwrap_or(cfg.width);
                if w == 0 {
                    return Err(invalid("--width must be at least 1"));
                }
                Architecture::SidUnet(cfg.with_width(w))
            }
            Method::Pgrf => {
                let d = Sr3Config::new();
                let inner = self
                    .inner_channels
                    .or(self.width)
                    .unwrap_or(d.inner_channels);
                let mults = self.channel_mults.clone().unwrap_or(d.channel_mults);
                let attn = self.attn_levels.clone().unwrap_or(d.attn_levels);
                if let Some(l) = attn.iter().find(|&&l| l >= mults.len()) {
                    return Err(invalid(format!(
                        "--attn-levels {l} does not exist: the network has {} levels (0..{})",
                        mults.len(),
                        mults.len().saturating_sub(1)
                    )));
                }
                let groups = self
                    .norm_groups
                    .unwrap_or_else(|| default_groups(inner, &mults));
                let cfg = Sr3Config::new()
                    .with_inner_channels(inner)
                    .with_channel_mults(mults)
                    .with_res_blocks(self.res_blocks.unwrap_or(d.res_blocks))
                    .with_attn_levels(attn)
                    .with_norm_groups(groups)
                    .with_dropout(self.dropout.unwrap_or(d.dropout))
                    .with_residual(self.residual);
                cfg.validate()
                    .map_err(|e| invalid(format!("flow network: {e}")))?;
                Architecture::Sr3(cfg)
            }
        })
    }

    /// The ISO range as (low, high), checked: two positive ISOs, ordered,
    /// and not given together with a fixed ISO.
    pub fn iso_range(&self) -> Result<Option<(u32, u32)>> {
        let Some(r) = &self.iso_range else {
            return Ok(None);
        };
        match r.as_slice() {
            [lo, hi] if *lo > 0 && hi >= lo => {
                if self.iso.is_some() {
                    return Err(invalid("give --iso or --iso-range, not both"));
                }
                Ok(Some((*lo, *hi)))
            }
            _ => Err(invalid(format!(
                "--iso-range takes two positive ISOs, low first (got {r:?})"
            ))),
        }
    }

    /// Side of the validation crops.
    pub fn val_patch(&self) -> usize {
        self.val_patch.unwrap_or(self.patch.min(256))
    }

    /// Checks that need no files: sizes, the ratio range.
    pub fn validate(&self) -> Result<()> {
        if self.patch < 8 || self.batch == 0 {
            return Err(invalid(format!(
                "--patch must be at least 8 and --batch at least 1 (got {}, {})",
                self.patch, self.batch
            )));
        }
        let (lo, hi) = (self.ratio_min, self.ratio_max);
        if !(lo > 0.0 && hi >= lo && hi.is_finite()) {
            return Err(invalid(format!(
                "ratio range {lo}..{hi} must be positive and ordered"
            )));
        }
        if let Some(c) = self.clip_grad {
            if !(c.is_finite() && c > 0.0) {
                return Err(invalid(format!(
                    "--clip-grad must be a positive number (the largest gradient norm), got {c}"
                )));
            }
        }
        if self.photo_downscale == 0 {
            return Err(invalid("--photo-downscale must be at least 1"));
        }
        let w = self.photo_wb_spread;
        if !(w.is_finite() && (1.0..=4.0).contains(&w)) {
            return Err(invalid(format!(
                "--photo-wb-spread must be between 1 (no variation) and 4, got {w}"
            )));
        }
        let t = self.time_max;
        if !(t.is_finite() && t > 0.0 && t <= 1.0) {
            return Err(invalid(format!(
                "--time-max must be in (0, 1] (the flow's training times are drawn from U(0, time-max)), got {t}"
            )));
        }
        self.iso_range()?;
        Ok(())
    }
}

/// The largest group count <= 32 that divides every level's channel count, so
/// reduced configurations work without the user doing the arithmetic.
fn default_groups(inner: usize, mults: &[usize]) -> usize {
    (1..=32usize)
        .rev()
        .find(|&g| inner.is_multiple_of(g) && mults.iter().all(|m| (m * inner).is_multiple_of(g)))
        .unwrap_or(1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn toml_round_trip_keeps_every_setting() {
        let mut c = TrainConfig {
            steps: 1234,
            iso: Some(3200),
            channel_mults: Some(vec![1, 2, 2, 4]),
            clip_grad: Some(1.0),
            noise: ModelKind::Eld,
            ..TrainConfig::default()
        };
        c.output = Some("m.safetensors".into());
        let back = TrainConfig::from_toml(&c.to_toml()).unwrap();
        assert_eq!(back, c);
        // A partial file takes the defaults for the rest.
        let p = TrainConfig::from_toml("steps = 7\nratio_min = 50.0\n").unwrap();
        assert_eq!(p.steps, 7);
        assert_eq!(p.ratio_min, 50.0);
        assert_eq!(p.ratio_max, TrainConfig::default().ratio_max);
        // Unknown keys are named.
        let e = TrainConfig::from_toml("stepz = 7\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("stepz"), "{e}");
    }

    #[test]
    fn overlay_replaces_only_given_keys() {
        #[derive(Serialize)]
        struct Flags {
            steps: Option<u64>,
            lr: Option<f64>,
        }
        let file = TrainConfig::from_toml("steps = 10\nbatch = 3\n").unwrap();
        let c = file
            .overlay(&Flags {
                steps: Some(99),
                lr: None,
            })
            .unwrap();
        assert_eq!((c.steps, c.batch, c.lr), (99, 3, 1e-4));
    }

    #[test]
    fn architecture_defaults_come_from_the_network_configs() {
        let c = TrainConfig::default();
        let Architecture::Sr3(s) = c.architecture(Method::Pgrf).unwrap() else {
            panic!("flow")
        };
        assert_eq!(s.channel_mults, Sr3Config::new().channel_mults);
        assert_eq!(s.norm_groups, 32);
        let small = TrainConfig {
            inner_channels: Some(24),
            channel_mults: Some(vec![1, 2]),
            attn_levels: Some(vec![1]),
            ..TrainConfig::default()
        };
        let Architecture::Sr3(s) = small.architecture(Method::Pgrf).unwrap() else {
            panic!("flow")
        };
        assert_eq!(s.norm_groups, 24);
        let bad = TrainConfig {
            attn_levels: Some(vec![5]),
            ..TrainConfig::default()
        };
        assert!(bad.architecture(Method::Pgrf).is_err());
        let Architecture::SidUnet(u) = c.architecture(Method::Spc).unwrap() else {
            panic!("spc")
        };
        assert_eq!(u.width, SidUnetConfig::new().width);
    }
}
