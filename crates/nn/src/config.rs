//! The training configuration: every setting of `pgrf train`, with each
//! default stated once (here, or in the network configurations it defers
//! to), read from and written as TOML, and stored in the weight file it
//! produced so that a run can be repeated from its result.
//!
//! Keys are the command-line flags with underscores (`--ratio-min` is
//! `ratio_min`); a file may hold any subset and the flags override it.

use crate::arch::{Architecture, PriorFlowConfig, SidUnetConfig, Sr3Config};
use crate::condition::Conditioning;
use crate::error::{NnError, Result};
use crate::schedule::Schedule;
use pgrf_noise::ModelKind;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The most optimiser steps a run may ask for: the paper's runs take 10^5
/// to 10^6, and the run keeps one loss per step.
pub const MAX_STEPS: u64 = 1_000_000_000;

/// The most data threads a run may ask for: beyond the cores a machine has
/// they only queue batches (each holding memory), and a thread per request
/// would run the process out of them.
pub const MAX_WORKERS: usize = 64;

pub use crate::arch::Method;

/// Every training setting, the one type behind the `--config` TOML file,
/// `pgrf train`'s flags (with the `clap` feature: each field's doc comment
/// is its flag's help, and `flags::TrainFlags` overlays the flags a
/// user gave), the record in the weight file and the checkpoint's run.
/// `None` means "derived": from the network configuration's own default
/// (`width`, SR3 sizes), from another setting (`val_patch` from `patch`,
/// `checkpoint` and `log` from `output`), or not used (`clip_grad`, `iso`,
/// `calib`). Keys are the flags with underscores.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
#[serde(default, deny_unknown_fields)]
pub struct TrainConfig {
    /// Clean training images, comma-separated entries `SOURCE[@WEIGHT]`: a folder (or file) of clean RAWs, a folder of photos (JPEG/PNG/TIFF, unprocessed into the camera's RAW space), or "procedural" (dead-leaves scenes); crops are drawn in proportion to the weights (default 1 each), e.g. `photos/@3,procedural@1` [default: procedural].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().data, hide_default_value = true))]
    pub data: String,
    /// Validation images, entries as --data (default: 10% of each folder's files held out; procedural entries validate on procedural scenes).
    #[cfg_attr(feature = "clap", arg(long))]
    pub val_data: Option<String>,
    /// Camera noise profile (built-in name, darktable:"MAKER MODEL", dng:FILE.dng or JSON path), or a mix `NAME[@WEIGHT],...` where each crop draws one camera's noise, e.g. sony-a7s2@3,nikon-d850@1; --iso/--iso-range are the first profile's, and become a gain range the others share [default: sony-a7s2].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().profile, hide_default_value = true))]
    pub profile: String,
    /// Per-pixel calibration file (from `pgrf calibrate`) for the pgrf noise model.
    #[cfg_attr(feature = "clap", arg(long))]
    pub calib: Option<PathBuf>,
    /// Draw the pairs' read, row and quantisation noise from --calib's noise bank (its bias frames' residuals) instead of the parametric model.
    #[cfg_attr(feature = "clap", arg(long, action = clap::ArgAction::Set, num_args = 0..=1, default_missing_value = "true", default_value_t = false, hide_default_value = true))]
    #[serde(default, skip_serializing_if = "is_false")]
    pub noise_bank: bool,
    /// Noise model of the synthetic pairs: pg, eld or pgrf [default: pgrf] (`--noise`, its old name, still works).
    #[cfg_attr(feature = "clap", arg(long = "noise-model", alias = "noise", default_value_t = d().noise, hide_default_value = true))]
    pub noise: ModelKind,
    /// Fixed ISO (default: parameters drawn from the profile's ELD distribution).
    #[cfg_attr(feature = "clap", arg(long))]
    pub iso: Option<u32>,
    /// Draw the gain between two ISOs only, e.g. 800,6400 (default: the profile's whole range).
    #[cfg_attr(feature = "clap", arg(long, value_delimiter = ','))]
    pub iso_range: Option<Vec<u32>>,
    /// The camera photos are unprocessed into: any RAW file of it (colour matrix, white balance, CFA, levels) [default: the built-in A7S2's with the sony-a7s2 profile].
    #[cfg_attr(feature = "clap", arg(long))]
    pub camera_like: Option<PathBuf>,
    /// Photos: downscale factor per side before cropping (area filter; removes JPEG and demosaicing artefacts) [default: 2].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().photo_downscale, hide_default_value = true))]
    pub photo_downscale: usize,
    /// Photos: invert a global S-shaped tone curve (Brooks et al.'s smoothstep) before the sRGB transfer.
    #[cfg_attr(feature = "clap", arg(long, action = clap::ArgAction::Set, num_args = 0..=1, default_missing_value = "true", default_value_t = false, hide_default_value = true))]
    pub photo_inverse_tone: bool,
    /// Photos: largest factor by which each crop's red and blue white-balance multipliers are varied (log-uniform in [1/S, S]); 1.25 spans one camera's daylight, shade and flash, 2.5 reaches cameras whose raw channels are nearly balanced [default: 1.25].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().photo_wb_spread, hide_default_value = true))]
    pub photo_wb_spread: f32,
    /// Smallest exposure ratio [default: 1].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().ratio_min, hide_default_value = true))]
    pub ratio_min: f32,
    /// Largest exposure ratio [default: 300].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().ratio_max, hide_default_value = true))]
    pub ratio_max: f32,
    /// How ratios are drawn between --ratio-min and --ratio-max: uniform, or log (every factor of the range equally often: as many crops below x20 as above it for 1..300) [default: uniform].
    #[cfg_attr(feature = "clap", arg(long, value_enum, default_value_t = d().ratio_draw, hide_default_value = true))]
    #[serde(skip_serializing_if = "is_uniform")]
    pub ratio_draw: RatioDraw,
    /// Side of the packed training crops [default: 512].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().patch, hide_default_value = true))]
    pub patch: usize,
    /// Crops per step [default: 1].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().batch, hide_default_value = true))]
    pub batch: usize,
    /// Data worker threads [default: 2].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().workers, hide_default_value = true))]
    pub workers: usize,
    /// Memory for decoded training RAWs, MiB [default: 4096].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().cache_mib, hide_default_value = true))]
    pub cache_mib: usize,
    /// Optimisation steps, at most 10^9 [default: 30000].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().steps, hide_default_value = true, value_parser = clap::value_parser!(u64).range(..=MAX_STEPS)))]
    pub steps: u64,
    /// Base learning rate [default: 1e-4].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().lr, hide_default_value = true))]
    pub lr: f64,
    /// Learning-rate schedule: eld (1/2 at 50%, 1/10 at 90%), constant or cosine [default: eld].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().schedule, hide_default_value = true))]
    pub schedule: Schedule,
    /// Clip each parameter's gradient to this norm.
    #[cfg_attr(feature = "clap", arg(long))]
    pub clip_grad: Option<f32>,
    /// Seed of initialisation, crops, noise, X0 and t [default: 0].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().seed, hide_default_value = true))]
    #[serde(with = "crate::seeded::wide_seed")]
    pub seed: u64,
    /// Turn off flips and transposes.
    #[cfg_attr(feature = "clap", arg(long, action = clap::ArgAction::Set, num_args = 0..=1, default_missing_value = "true", default_value_t = false, hide_default_value = true))]
    pub no_augment: bool,
    /// Train on captures without the camera's dark-level offset (black-level error, colour bias): for input calibrated by `pgrf enhance --calib` (or the synthetic protocol); recorded in the weight file. Without it the network learns to guess an offset it cannot see, and subtracts the average guess from calibrated inputs too (a tint in dark areas).
    #[cfg_attr(feature = "clap", arg(long, action = clap::ArgAction::Set, num_args = 0..=1, default_missing_value = "true", default_value_t = false, hide_default_value = true))]
    pub calibrated_dark_level: bool,
    /// Without --calibrated-dark-level: the share of captures drawn without the offset all the same (0..1), so that one network serves uncalibrated and calibrated input [default: 0].
    #[cfg_attr(
        feature = "clap",
        arg(long, default_value_t = 0.0, hide_default_value = true)
    )]
    #[serde(skip_serializing_if = "is_zero")]
    pub calibrated_share: f64,
    /// Feed the network the capture's values below black as recorded (negative after the black is subtracted; only white clips) instead of clamping them at 0 as SID does: the clamp lifts dark areas and removes half of the read noise a denoiser needs to see (MODELS.md, issue 51). Recorded in the network's configuration; enhance, eval and search feed the network as it was trained.
    #[cfg_attr(feature = "clap", arg(long, action = clap::ArgAction::Set, num_args = 0..=1, default_missing_value = "true", default_value_t = false, hide_default_value = true))]
    #[serde(skip_serializing_if = "is_false")]
    pub keep_below_black: bool,
    /// How each crop's loss counts: none (every pixel alike: the noisiest crops dominate), noise (each crop's error over its noise level) or log (each crop's error over its own current value: the mean of ln L1, so every crop's dB counts alike) [default: none].
    #[cfg_attr(feature = "clap", arg(long, value_enum, default_value_t = d().item_weight, hide_default_value = true))]
    #[serde(skip_serializing_if = "is_unweighted")]
    pub item_weight: ItemWeight,
    /// The distance the loss averages: l1 (the papers') or mse (what PSNR measures; with --item-weight log the loss is the mean over crops of ln MSE, whose gradient is the mean PSNR's) [default: l1].
    #[cfg_attr(feature = "clap", arg(long, value_enum, default_value_t = d().loss, hide_default_value = true))]
    #[serde(skip_serializing_if = "is_l1")]
    pub loss: Distance,
    /// Width of the first level: SID U-Net channels [default: 32]; for the flow model the SR3 inner channels unless --inner-channels is given.
    #[cfg_attr(feature = "clap", arg(long))]
    pub width: Option<usize>,
    /// Learn a correction: the SID U-Net adds its input to its output; the flow model adds T - Xt to its velocity (its first stage starts as the noisy input). Not the papers' design; converges far faster for small CPU-trained models.
    #[cfg_attr(feature = "clap", arg(long, action = clap::ArgAction::Set, num_args = 0..=1, default_missing_value = "true", default_value_t = false, hide_default_value = true))]
    pub residual: bool,
    /// Tell the network how noisy its input is (MODELS.md, "Noise-aware models"): none (it guesses from the pixels), sigma-map (four more input planes, the noise standard deviation at each pixel), k-sigma (the input mapped so that its noise is the same at every gain, the output mapped back) or log-sigma-map (the sigma planes as their centred log: the scale of the image planes) [default: none].
    #[cfg_attr(feature = "clap", arg(long, value_enum, default_value_t = d().conditioning, hide_default_value = true))]
    #[serde(skip_serializing_if = "is_unconditioned")]
    pub conditioning: Conditioning,
    /// Start from this weight file's weights (a trained network of this configuration, e.g. models/spc.safetensors; or the same network without noise conditioning, whose noise planes then start at zero weights; or a narrower SID U-Net, whose channels start a wider one computing what it did) instead of fresh ones: fine-tuning on other data or conditions; the optimiser and the learning-rate schedule start afresh (a resumed run takes its weights from the checkpoint), and the output records the file and its training.
    #[cfg_attr(feature = "clap", arg(long))]
    pub init: Option<PathBuf>,
    /// PGRF only: start the flow from this SPC weight file's restoration (MODELS.md, "The flow from the SPC's restoration"): the velocity field reads the frozen denoiser's output as four more planes and corrects it instead of the noisy input, so that a fresh field samples exactly what the SPC restores; the denoiser is stored in the flow's weight file and never trained.
    #[cfg_attr(feature = "clap", arg(long))]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub prior: Option<PathBuf>,
    /// SR3 channels of the first level [default: 64, or --width].
    #[cfg_attr(feature = "clap", arg(long))]
    pub inner_channels: Option<usize>,
    /// SR3 channel multipliers per level, comma-separated [default: 1,2,4,8,8].
    #[cfg_attr(feature = "clap", arg(long, value_delimiter = ','))]
    pub channel_mults: Option<Vec<usize>>,
    /// SR3 residual blocks per level [default: 2].
    #[cfg_attr(feature = "clap", arg(long))]
    pub res_blocks: Option<usize>,
    /// SR3 levels with self-attention (0 = full resolution), comma-separated [default: 3].
    #[cfg_attr(feature = "clap", arg(long, value_delimiter = ','))]
    pub attn_levels: Option<Vec<usize>>,
    /// Flow model: take GroupNorm and attention statistics over windows of this side (packed pixels) of each crop, as a frame is restored (MODELS.md, "PGRF independent of the tiling"); crops of 2 x 2 windows teach the network the window borders it meets in a frame. Recorded; inference uses it. [default: none: each crop whole, its side the window at inference].
    #[cfg_attr(feature = "clap", arg(long))]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub window: Option<usize>,
    /// SR3 GroupNorm groups [default: 32, or fewer to divide the channels].
    #[cfg_attr(feature = "clap", arg(long))]
    pub norm_groups: Option<usize>,
    /// SR3 dropout [default: 0].
    #[cfg_attr(feature = "clap", arg(long))]
    pub dropout: Option<f64>,
    /// Validate every N steps (0: only at the end) [default: 1000].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().val_every, hide_default_value = true))]
    pub val_every: u64,
    /// Validation pairs [default: 4].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().val_pairs, hide_default_value = true))]
    pub val_pairs: usize,
    /// Side of the validation crops [default: min(patch, 256)].
    #[cfg_attr(feature = "clap", arg(long))]
    pub val_patch: Option<usize>,
    /// t2 of the two-stage sampler when validating the flow model [default: 0.5].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().val_t2, hide_default_value = true))]
    pub val_t2: f32,
    /// Flow model: draw the training time t from U(0, TIME_MAX) instead of U(0, 1) (Algorithm 1), in (0, 1]: spend the training on the times the two-stage sampler uses (t = 0 and t2), e.g. 0.5; recorded in the weight file [default: 1]. The residual field's L1 loss weighs late times up to ten times more (MODELS.md, "The calibrated measure"); the Euler sampler and the search's t above it leave what the field learned.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().time_max, hide_default_value = true))]
    pub time_max: f32,
    /// Keep an exponential moving average of the weights with this decay per step, in (0, 1), e.g. 0.999 (the first steps use the smaller (1 + step) / (10 + step)): validation scores the average and the raw weights, and the weight file holds the average [default: none].
    #[cfg_attr(feature = "clap", arg(long))]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ema: Option<f32>,
    /// Checkpoint every N steps [default: 1000].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().checkpoint_every, hide_default_value = true))]
    pub checkpoint_every: u64,
    /// Checkpoint file [default: OUTPUT with extension .ckpt].
    #[cfg_attr(feature = "clap", arg(long))]
    pub checkpoint: Option<PathBuf>,
    /// Log file, CSV (or JSON lines if it ends in .jsonl) [default: OUTPUT with extension .log.csv].
    #[cfg_attr(feature = "clap", arg(long))]
    pub log: Option<PathBuf>,
    /// Log the mean loss every N steps [default: 10].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().log_every, hide_default_value = true))]
    pub log_every: u64,
    /// Weight file to write.
    #[cfg_attr(feature = "clap", arg(short = 'o', long = "output"))]
    pub output: Option<PathBuf>,
    /// cpu or cuda [default: cpu].
    #[cfg_attr(feature = "clap", arg(long, default_value_t = d().device, hide_default_value = true))]
    pub device: crate::backend::DeviceKind,
    /// Whose CPU operations the run uses ([`crate::ops::Kernels`]): set by
    /// the caller (the command line's global `--kernels`), not a setting of
    /// the run, so neither configuration files nor weight records hold it.
    #[cfg_attr(feature = "clap", arg(skip))]
    #[serde(skip)]
    pub kernels: crate::ops::Kernels,
    /// darktable's noiseprofiles.json for `darktable:` profiles, set by the
    /// caller like `kernels` (the command line's global
    /// `--darktable-profiles`; None: darktable's install is searched).
    #[cfg_attr(feature = "clap", arg(skip))]
    #[serde(skip)]
    pub darktable_profiles: Option<PathBuf>,
}

/// The distance between output and target the loss averages (`pgrf train
/// --loss`); `loss::batch_loss` applies it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Distance {
    /// Mean absolute error: the papers' loss (SID, ELD, Algorithm 1).
    #[default]
    L1,
    /// Mean squared error: what PSNR measures.
    Mse,
}

/// What a training step minimises: the distance and how the batch's items
/// count (`loss::batch_loss`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LossRule {
    /// Per-element distance.
    pub distance: Distance,
    /// Per-item weighting.
    pub weight: ItemWeight,
}

impl TrainConfig {
    /// The loss this configuration trains with.
    pub fn loss_rule(&self) -> LossRule {
        LossRule {
            distance: self.loss,
            weight: self.item_weight,
        }
    }
}

/// Records of L1 runs stay as they were (no `loss`).
fn is_l1(d: &Distance) -> bool {
    *d == Distance::L1
}

/// How each item of a training batch counts in the loss (`pgrf train
/// --item-weight`); `loss::batch_loss` applies it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum ItemWeight {
    /// Every element alike: the batch's mean absolute error (every run
    /// before issue 51). The noisiest items' errors are the largest, so they
    /// dominate the sum.
    #[default]
    None,
    /// Each item's mean error divided by its noise standard deviation at its
    /// mean level: an item at x1-x20 counts as much as one at x300.
    Noise,
    /// Each item's mean distance divided by its own current value (not
    /// differentiated): the gradient of the mean of its logarithm over the
    /// items, so a tenth less error counts alike at every noise level, as a
    /// mean of PSNRs in dB does (with `--loss mse`, exactly the gradient of
    /// the mean PSNR).
    Log,
}

/// Records of unweighted runs stay as they were (no `item_weight`).
fn is_unweighted(w: &ItemWeight) -> bool {
    *w == ItemWeight::None
}

/// Records of runs that clamped the input at black stay as they were.
fn is_false(v: &bool) -> bool {
    !*v
}

/// How `pgrf train` draws each crop's exposure ratio in its range.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum RatioDraw {
    /// Uniform in the range (every run before issue 36's second stage).
    #[default]
    Uniform,
    /// ln ratio uniform: low ratios (low noise) as often as high ones.
    Log,
}

impl RatioDraw {
    /// The pair synthesis' spec for the range `lo..hi`.
    pub fn spec(self, lo: f32, hi: f32) -> pgrf_noise::pair::RatioSpec {
        use pgrf_noise::pair::RatioSpec;
        match self {
            RatioDraw::Uniform => RatioSpec::Uniform { lo, hi },
            RatioDraw::Log => RatioSpec::LogUniform { lo, hi },
        }
    }
}

/// Records of runs with uniform ratios stay as they were (no `ratio_draw`).
fn is_uniform(r: &RatioDraw) -> bool {
    *r == RatioDraw::Uniform
}

/// Records of runs without a calibrated share stay as they were.
fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// Records of unconditioned runs stay as they were before conditioning
/// existed (no `conditioning` key).
fn is_unconditioned(c: &Conditioning) -> bool {
    *c == Conditioning::None
}

/// The defaults the flags show (the same as [`TrainConfig::default`]).
#[cfg(feature = "clap")]
fn d() -> TrainConfig {
    TrainConfig::default()
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
            photo_wb_spread: pgrf_scenes::unprocess::WB_SPREAD,
            ratio_min: 1.0,
            ratio_max: 300.0,
            ratio_draw: RatioDraw::Uniform,
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
            calibrated_share: 0.0,
            noise_bank: false,
            keep_below_black: false,
            item_weight: ItemWeight::None,
            loss: Distance::L1,
            width: None,
            residual: false,
            conditioning: Conditioning::None,
            init: None,
            prior: None,
            inner_channels: None,
            channel_mults: None,
            res_blocks: None,
            attn_levels: None,
            window: None,
            norm_groups: None,
            dropout: None,
            val_every: 1000,
            val_pairs: 4,
            val_patch: None,
            val_t2: 0.5,
            time_max: 1.0,
            ema: None,
            checkpoint_every: 1000,
            checkpoint: None,
            log: None,
            log_every: 10,
            output: None,
            device: crate::backend::DeviceKind::Cpu,
            kernels: crate::ops::Kernels::Pgrf,
            darktable_profiles: None,
        }
    }
}

/// A setting `flag` refused, `message` saying why (naming the flag).
fn bad(flag: &'static str, message: impl Into<String>) -> NnError {
    NnError::BadSetting {
        flag,
        message: message.into(),
    }
}

/// The files a training run writes, resolved from the configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainOutputs {
    /// The weight file (`output`).
    pub weights: PathBuf,
    /// The checkpoint (`checkpoint`, else the output with extension .ckpt).
    pub checkpoint: PathBuf,
    /// The log (`log`, else the output with extension .log.csv).
    pub log: PathBuf,
}

impl TrainConfig {
    /// Read a `--config` file (any subset of the keys); errors name the file.
    pub fn from_file(path: &Path) -> Result<TrainConfig> {
        let bad = |reason: String| NnError::BadConfigFile {
            path: path.to_path_buf(),
            reason,
        };
        let text = std::fs::read_to_string(path).map_err(|e| bad(e.to_string()))?;
        TrainConfig::from_toml(&text).map_err(|e| bad(e.to_string()))
    }

    /// The configuration of `pgrf train`: the defaults, then the `--config`
    /// file `file` (if any), then `over` (the flags given), checked for
    /// training `method` ([`TrainConfig::check_for`]).
    pub fn merged<T: Serialize>(
        file: Option<&Path>,
        over: &T,
        method: Method,
    ) -> Result<TrainConfig> {
        let base = match file {
            None => TrainConfig::default(),
            Some(p) => TrainConfig::from_file(p)?,
        };
        let c = base.overlay(over)?;
        c.check_for(method)?;
        Ok(c)
    }

    /// [`TrainConfig::validate`], and what only the other method has:
    /// the flow's training time range is refused for the SPC denoiser.
    pub fn check_for(&self, method: Method) -> Result<()> {
        self.validate()?;
        if method == Method::Spc && self.time_max != 1.0 {
            return Err(NnError::BadSetting {
                flag: "--time-max",
                message:
                    "--time-max is the flow model's training time range; the SPC denoiser has none"
                        .into(),
            });
        }
        if let Some(w) = self.window {
            if method == Method::Spc {
                return Err(bad(
                    "--window",
                    "--window is the flow model's statistics windows; the SPC denoiser takes no statistics",
                ));
            }
            if w == 0 || !self.patch.is_multiple_of(w) {
                return Err(bad(
                    "--window",
                    format!(
                        "--window {w} must divide --patch {} (crops of whole windows)",
                        self.patch
                    ),
                ));
            }
            let val = self.val_patch.unwrap_or(self.patch);
            if !val.is_multiple_of(w) {
                return Err(bad(
                    "--window",
                    format!("--window {w} must divide --val-patch {val} (validation crops of whole windows)"),
                ));
            }
        }
        Ok(())
    }

    /// The files a run writes: the weight file (refused when `output` is
    /// not set), the checkpoint and the log.
    pub fn outputs(&self) -> Result<TrainOutputs> {
        let Some(out) = self.output.clone() else {
            return Err(NnError::BadSetting {
                flag: "-o",
                message: "no output: give -o FILE.safetensors (or `output = ...` in the config)"
                    .into(),
            });
        };
        Ok(TrainOutputs {
            checkpoint: self
                .checkpoint
                .clone()
                .unwrap_or_else(|| out.with_extension("ckpt")),
            log: self
                .log
                .clone()
                .unwrap_or_else(|| out.with_extension("log.csv")),
            weights: out,
        })
    }

    /// Parse a TOML file's text (any subset of the keys; unknown keys are
    /// refused with their name).
    pub fn from_toml(text: &str) -> Result<TrainConfig> {
        toml::from_str(text).map_err(|e| NnError::Config(e.message().to_string()))
    }

    /// The whole configuration as TOML (unset optional keys left out).
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("a TrainConfig always serialises")
    }

    /// This configuration with the keys of `over` (e.g. the flags a user
    /// gave) replacing its own; `over` is checked like a file.
    pub fn overlay<T: Serialize>(&self, over: &T) -> Result<TrainConfig> {
        let table = |e: toml::ser::Error| NnError::Config(e.to_string());
        let mut base = toml::Table::try_from(self).map_err(table)?;
        let top = toml::Table::try_from(over).map_err(table)?;
        base.extend(top);
        base.try_into::<TrainConfig>()
            .map_err(|e| NnError::Config(e.message().to_string()))
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
                    return Err(bad("--iso-range", "give --iso or --iso-range, not both"));
                }
                Ok(Some((*lo, *hi)))
            }
            _ => Err(bad(
                "--iso-range",
                format!("--iso-range takes two positive ISOs, low first (got {r:?})"),
            )),
        }
    }

    /// Side of the validation crops.
    pub fn val_patch(&self) -> usize {
        self.val_patch.unwrap_or(self.patch.min(256))
    }

    /// Checks that need no files: sizes, the ratio range.
    pub fn validate(&self) -> Result<()> {
        if self.patch < 8 || self.batch == 0 {
            return Err(bad(
                "--patch",
                format!(
                    "--patch must be at least 8 and --batch at least 1 (got {}, {})",
                    self.patch, self.batch
                ),
            ));
        }
        let (lo, hi) = (self.ratio_min, self.ratio_max);
        for (flag, r) in [("--ratio-min", lo), ("--ratio-max", hi)] {
            pgrf_noise::pair::ratio_in_range(flag, r).map_err(|e| bad(flag, e.to_string()))?;
        }
        if hi < lo {
            return Err(bad(
                "--ratio-min",
                format!("ratio range {lo}..{hi} must be ordered"),
            ));
        }
        if let Some(c) = self.clip_grad {
            if !(c.is_finite() && c > 0.0) {
                return Err(bad(
                    "--clip-grad",
                    format!(
                    "--clip-grad must be a positive number (the largest gradient norm), got {c}"
                ),
                ));
            }
        }
        if self.steps > MAX_STEPS {
            return Err(bad(
                "--steps",
                format!(
                    "--steps must be at most {MAX_STEPS} (the log keeps a loss per step), got {}",
                    self.steps
                ),
            ));
        }
        if !(1..=MAX_WORKERS).contains(&self.workers) {
            return Err(bad(
                "--workers",
                format!(
                    "--workers is a number of data threads, 1 to {MAX_WORKERS}, got {}",
                    self.workers
                ),
            ));
        }
        self.validate_data()?;
        self.validate_schedule()
    }

    /// [`TrainConfig::validate`]'s checks of the photos' settings.
    fn validate_data(&self) -> Result<()> {
        if self.photo_downscale == 0 {
            return Err(bad(
                "--photo-downscale",
                "--photo-downscale must be at least 1",
            ));
        }
        let w = self.photo_wb_spread;
        if !(w.is_finite() && (1.0..=4.0).contains(&w)) {
            return Err(bad(
                "--photo-wb-spread",
                format!("--photo-wb-spread must be between 1 (no variation) and 4, got {w}"),
            ));
        }
        Ok(())
    }

    /// [`TrainConfig::validate`]'s checks of the averaging, the flow's
    /// times, the calibrated share and the ISO range.
    fn validate_schedule(&self) -> Result<()> {
        if let Some(d) = self.ema {
            if !(d.is_finite() && d > 0.0 && d < 1.0) {
                return Err(bad(
                    "--ema",
                    format!("--ema is the moving average's decay per step, in (0, 1) (e.g. 0.999), got {d}"),
                ));
            }
        }
        let t = self.time_max;
        if !(t.is_finite() && t > 0.0 && t <= 1.0) {
            return Err(bad("--time-max", format!(
                "--time-max must be in (0, 1] (the flow's training times are drawn from U(0, time-max)), got {t}"
            )));
        }
        let share = self.calibrated_share;
        if !(0.0..=1.0).contains(&share) {
            return Err(bad(
                "--calibrated-share",
                format!("--calibrated-share is a share of the captures, in [0, 1], got {share}"),
            ));
        }
        if share > 0.0 && self.calibrated_dark_level {
            return Err(bad(
                "--calibrated-share",
                "--calibrated-share goes without --calibrated-dark-level (which draws every capture calibrated)",
            ));
        }
        if self.noise_bank && self.calib.is_none() {
            return Err(bad("--noise-bank", pgrf_noise::bank::NEEDS_CALIBRATION));
        }
        if self.noise_bank && self.noise != ModelKind::Pgrf {
            return Err(bad(
                "--noise-bank",
                pgrf_noise::bank::needs_pgrf_model("--noise"),
            ));
        }
        self.iso_range()?;
        Ok(())
    }
}

impl TrainConfig {
    /// The network this configuration trains for `method`, checked.
    /// With a `prior`, its file's record is read (not its tensors).
    pub fn architecture(&self, method: Method) -> Result<Architecture> {
        Ok(match (method, &self.prior) {
            (Method::Spc, None) => Architecture::SidUnet(self.sid_unet()?),
            (Method::Pgrf, None) => Architecture::Sr3(self.sr3()?),
            (Method::Pgrf, Some(path)) => {
                Architecture::Sr3Prior(PriorFlowConfig::new(self.sr3()?, prior_denoiser(path)?))
            }
            (Method::Spc, Some(_)) => {
                return Err(NnError::BadSetting {
                    flag: "--prior",
                    message: "--prior starts a flow model (pgrf train pgrf), not the SPC denoiser"
                        .into(),
                })
            }
        })
    }

    /// The network `pgrf train spc` builds from `c`: SID's defaults, the
    /// width `c.width` when given (at least 1), residual as `c.residual`.
    fn sid_unet(&self) -> Result<SidUnetConfig> {
        let c = self;
        let cfg = SidUnetConfig::new()
            .with_residual(c.residual)
            .with_conditioning(c.conditioning)
            .with_keep_below_black(c.keep_below_black)
            .with_in_channels(4 + c.conditioning.extra_channels());
        let w = c.width.unwrap_or(cfg.width);
        if w == 0 {
            return Err(NnError::Config("--width must be at least 1".into()));
        }
        Ok(cfg.with_width(w))
    }

    /// The network `pgrf train pgrf` builds from `c`: SR3's defaults where
    /// a setting is not given (`width` stands for the inner channels when
    /// `inner_channels` is not), GroupNorm groups the largest count <= 32
    /// that divides every level, checked.
    fn sr3(&self) -> Result<Sr3Config> {
        let c = self;
        let d = Sr3Config::new();
        let inner = c.inner_channels.or(c.width).unwrap_or(d.inner_channels);
        let mults = c.channel_mults.clone().unwrap_or(d.channel_mults);
        let attn = c.attn_levels.clone().unwrap_or(d.attn_levels);
        if let Some(l) = attn.iter().find(|&&l| l >= mults.len()) {
            return Err(NnError::Config(format!(
                "--attn-levels {l} does not exist: the network has {} levels (0..{})",
                mults.len(),
                mults.len().saturating_sub(1)
            )));
        }
        let groups = c
            .norm_groups
            .unwrap_or_else(|| crate::arch::sr3::default_groups(inner, &mults));
        let cfg = Sr3Config::new()
            .with_inner_channels(inner)
            .with_channel_mults(mults)
            .with_res_blocks(c.res_blocks.unwrap_or(d.res_blocks))
            .with_attn_levels(attn)
            .with_norm_groups(groups)
            .with_dropout(c.dropout.unwrap_or(d.dropout))
            .with_residual(c.residual)
            .with_conditioning(c.conditioning)
            .with_keep_below_black(c.keep_below_black)
            .with_in_channels(8 + c.conditioning.extra_channels());
        cfg.validate()
            .map_err(|e| NnError::Config(format!("flow network: {e}")))?;
        Ok(cfg)
    }
}

/// The SID U-Net configuration of the SPC weight file `path` (a flow's
/// `prior`), checked to be one.
fn prior_denoiser(path: &Path) -> Result<SidUnetConfig> {
    match crate::weights::read_meta(path)?.arch {
        Architecture::SidUnet(c) => Ok(c),
        other => Err(NnError::BadSetting {
            flag: "--prior",
            message: format!(
                "--prior {}: holds {}, not an SPC denoiser",
                path.display(),
                other.describe()
            ),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arch::{Architecture, SidUnetConfig, Sr3Config};

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

    /// `noise_bank` round-trips through TOML, is left out of a record
    /// that does not use it, and is refused without a calibration.
    #[test]
    fn a_noise_bank_needs_a_calibration() {
        let c = TrainConfig {
            noise_bank: true,
            ..TrainConfig::default()
        };
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("--noise-bank") && e.contains("--calib"), "{e}");
        let with = TrainConfig {
            calib: Some("cal.safetensors".into()),
            ..c
        };
        assert_eq!(TrainConfig::from_toml(&with.to_toml()).unwrap(), with);
        // The bank stands for the pgrf model's terms only.
        let eld = TrainConfig {
            noise: ModelKind::Eld,
            ..with.clone()
        };
        let e = eld.validate().unwrap_err().to_string();
        assert!(e.contains("use --noise pgrf"), "{e}");
        assert!(!TrainConfig::default().to_toml().contains("noise_bank"));
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
