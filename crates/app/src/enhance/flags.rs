//! `pgrf enhance`'s flags (the `clap` feature), their checks, the
//! configuration and jobs they make, and the notes printed before the first
//! file: kept beside the recipe, so a new option is added in one crate.

use super::batch::{check_manifest, Batch, Shard};
use super::jobs::{plan_jobs, read_list, Previews};
use super::{CalibrationFile, EnhanceConfig, EnhanceError, RatioChoice};
use pgrf_calib::Calibration;
use pgrf_nn::backend::DeviceKind;
use pgrf_nn::flow::sample::SamplerKind;
use pgrf_nn::infer::restorer::UNSEARCHED_T2;
use pgrf_nn::infer::{check_tiling_args, Restore, SamplerChoice, Tiling};
use pgrf_nn::ops::Kernels;
use pgrf_nn::NnError;
use pgrf_noise::lookup::NoiseFlag;
use std::path::PathBuf;

/// The model `pgrf enhance` restores with when `--model` is not given: the
/// built-in SPC denoiser, noise-aware and one pass (a photographer has no
/// weight file).
pub const DEFAULT_MODEL: &str = "builtin:spc";

/// `pgrf enhance`'s flags (the input-opening options are the caller's).
#[derive(clap::Args, Debug)]
pub struct EnhanceFlags {
    /// Noisy RAW files, or folders of them (optional with --from-list).
    #[arg(required_unless_present = "from_list")]
    pub inputs: Vec<PathBuf>,
    /// Also enhance the files (or folders) listed in FILE, one path a line; blank lines and lines starting with # are skipped; relative paths are relative to the current folder (as `find . -name '*.CR2' > FILE` writes them).
    #[arg(long, value_name = "FILE")]
    pub from_list: Option<PathBuf>,
    /// Do only shard I of N (counted from 0): the files at positions I, I+N, I+2N, ... of the whole input list sorted by path, so N runs with the same arguments split the work without overlap.
    #[arg(long, value_name = "I/N", allow_hyphen_values = true)]
    pub shard: Option<String>,
    /// Leave a file whose DNG (and preview, with --png) already exists and reads back whole; a file cut short is redone.
    #[arg(long)]
    pub skip_existing: bool,
    /// Append one JSON line per file to FILE (input, output, png, status done|skipped|failed, seconds, noise, error, shard).
    #[arg(long, value_name = "FILE")]
    pub manifest: Option<PathBuf>,
    /// Weight file from `pgrf train` (SPC denoiser or PGRF flow model), or builtin:spc or builtin:pgrf, the built-in models [default: builtin:spc].
    #[arg(long, short = 'm')]
    pub model: Option<PathBuf>,
    /// Exposure ratio, 1 to 10000: the input is multiplied by it before denoising; `auto` (the default without --target-exposure) meters each frame, bringing its mean level (brightest 1 % left out) to 1/8 of white, ratio 1..300, and prints what it chose.
    #[arg(
        long,
        conflicts_with = "target_exposure",
        allow_hyphen_values = true,
        value_name = "R|auto"
    )]
    pub ratio: Option<RatioFlag>,
    /// Instead of --ratio: the exposure (seconds) to brighten to; the ratio is
    /// target / the file's exposure time (x --target-iso / the file's ISO).
    #[arg(long)]
    pub target_exposure: Option<f64>,
    /// With --target-exposure: the ISO of the target exposure (default: the file's).
    #[arg(long, requires = "target_exposure")]
    pub target_iso: Option<u32>,
    /// Calibration file (`pgrf calibrate`): subtract its fixed pattern and
    /// mean dark current before amplifying.
    #[arg(long)]
    pub calib: Option<PathBuf>,
    /// Apply a calibration of another camera or ISO anyway.
    #[arg(long)]
    pub force: bool,
    /// Output DNG or FITS (.fits, .fit, .fts) for one input file, or folder
    /// for the results (created if its parent exists); files keep their names
    /// with a .dng extension, .fits for FITS inputs [default: NAME.pgrf.dng
    /// beside each input file, NAME.pgrf.fits for a FITS input].
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Also write an sRGB preview: to this .png with one input, next to each
    /// DNG without a value.
    #[arg(long, num_args = 0..=1)]
    #[allow(clippy::option_option)]
    pub png: Option<Option<PathBuf>>,
    /// Tile side in packed pixels, at least 144 when the frame is tiled (default: from available memory on the CPU, 1024 on CUDA).
    #[arg(long)]
    pub tile: Option<usize>,
    /// Minimum overlap of neighbouring tiles, packed pixels, at least 64 [default: 64].
    #[arg(long)]
    pub overlap: Option<usize>,
    /// cpu, or cuda (needs a build with `--features cuda`).
    #[arg(long, default_value = "cpu")]
    pub device: DeviceKind,
    /// Flow model sampler: two-stage (the paper's, 2 evaluations), one-step, or euler:N.
    #[arg(long, default_value = "two-stage")]
    pub sampler: SamplerKind,
    /// Second time of the two-stage sampler (default: the file's searched t2).
    #[arg(long, allow_hyphen_values = true)]
    pub t2: Option<f32>,
    /// Flow model: average this many samples from different start noise.
    #[arg(long, default_value_t = 1)]
    pub samples: usize,
    /// Noise parameters of the inputs for a noise-aware model, K=GAIN,read=SIGMA[,row=SIGMA] in DN per electron and DN on the files' scale [default: from --calib, else the file's DNG NoiseProfile, darktable's or a built-in profile of its camera at its ISO, else estimated from the frame].
    #[arg(long, value_name = "K=..,read=..")]
    pub noise: Option<NoiseFlag>,
    /// Seed of the flow model's start noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// One JSON line per file on stdout.
    #[arg(long)]
    pub json: bool,
    /// No progress bar or notes.
    #[arg(long, short)]
    pub quiet: bool,
}

/// `--ratio`: a number, or `auto`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RatioFlag {
    /// Meter the frame ([`RatioChoice::Auto`]).
    Auto,
    /// This exposure ratio.
    Value(f32),
}

impl std::str::FromStr for RatioFlag {
    type Err = pgrf_core::parse::ParseError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s.eq_ignore_ascii_case("auto") {
            return Ok(RatioFlag::Auto);
        }
        s.trim().parse::<f32>().map(RatioFlag::Value).map_err(|_| {
            pgrf_core::parse::ParseError::malformed(
                s,
                format!("expected a number or auto, got {s:?}"),
            )
        })
    }
}

fn refused(flag: &'static str, message: String) -> NnError {
    NnError::BadSetting { flag, message }
}

impl EnhanceFlags {
    /// Refuse flag values no file can make right, before any work; then
    /// read the list, expand folders and plan every output ([`plan_jobs`],
    /// on the whole list: every shard agrees on it), and check the
    /// manifest's path.
    pub fn batch(&self) -> Result<Batch, NnError> {
        if let Some(RatioFlag::Value(r)) = self.ratio {
            pgrf_noise::pair::ratio_in_range("--ratio", r)
                .map_err(|e| refused("--ratio", e.to_string()))?;
        }
        if let Some(t) = self.t2 {
            if !(0.0..=1.0).contains(&t) {
                return Err(refused("--t2", format!("--t2 must be in [0, 1], got {t}")));
            }
        }
        check_tiling_args(self.tile, self.overlap)?;
        let shard = (self.shard.as_deref())
            .map(|s| {
                s.parse::<Shard>()
                    .map_err(|e| refused("--shard", e.to_string()))
            })
            .transpose()?;
        let mut given = self.inputs.clone();
        if let Some(list) = &self.from_list {
            given.extend(read_list(list)?);
        }
        if given.is_empty() {
            return Err(refused(
                "--from-list",
                "no inputs: the list names no files and none are given on the command line".into(),
            ));
        }
        let previews = match &self.png {
            None => Previews::None,
            Some(None) => Previews::BesideEach,
            Some(Some(p)) => Previews::At(p),
        };
        let jobs = plan_jobs(&given, self.output.as_deref(), previews)?;
        if let Some(m) = &self.manifest {
            check_manifest(m, &given, &jobs)?;
        }
        Ok(Batch {
            jobs,
            shard,
            skip_existing: self.skip_existing,
            manifest: self.manifest.clone(),
        })
    }

    /// How every file is enhanced (the calibration loaded), on pgrf's
    /// operations (the caller sets `tiling.kernels` to choose).
    pub fn config(&self) -> Result<EnhanceConfig, EnhanceError> {
        let calib = match &self.calib {
            Some(p) => Some(CalibrationFile {
                path: p.clone(),
                calibration: Calibration::load(p)
                    .map_err(|e| EnhanceError::LoadCalibration(Box::new(e)))?,
            }),
            None => None,
        };
        let ratio = match (self.ratio, self.target_exposure) {
            (Some(RatioFlag::Value(r)), _) => RatioChoice::Fixed(r),
            (Some(RatioFlag::Auto), _) | (None, None) => RatioChoice::Auto,
            (None, Some(seconds)) => RatioChoice::TargetExposure {
                seconds,
                iso: self.target_iso,
            },
        };
        Ok(EnhanceConfig {
            ratio,
            calib,
            force: self.force,
            noise: self.noise,
            masked_black: true,
            darktable: None,
            tiling: Tiling {
                tile: self.tile,
                overlap: self.overlap,
                seed: self.seed,
                device: self.device,
                kernels: Kernels::default(),
            },
        })
    }

    /// The weight file (or built-in model) to restore with: `--model`, else
    /// [`DEFAULT_MODEL`].
    pub fn model(&self) -> PathBuf {
        self.model
            .clone()
            .unwrap_or_else(|| PathBuf::from(DEFAULT_MODEL))
    }

    /// The flow model's sampler as the flags choose it.
    pub fn sampler(&self) -> SamplerChoice {
        SamplerChoice {
            kind: self.sampler,
            t2: self.t2,
            samples: self.samples,
        }
    }

    /// What the user should know about the model and device, printed
    /// before the first image is processed (so that an input that fails at
    /// once still gives a single line).
    pub fn notes(&self, restorer: &dyn Restore, kernels: Kernels) -> Vec<String> {
        let default = if self.model.is_none() {
            format!(" ({DEFAULT_MODEL}, the default without --model)")
        } else {
            String::new()
        };
        let mut lines = vec![format!(
            "model: {}{default}; device {}",
            super::describe_method(restorer),
            pgrf_nn::backend::describe(self.device, kernels)
        )];
        if restorer.sampler().is_some() && restorer.meta().t2.is_none() && self.t2.is_none() {
            lines.push(format!(
                "note: {} has no searched t2; using {UNSEARCHED_T2} (run `pgrf search` to find the best)",
                self.model().display(),
            ));
        }
        if restorer.meta().noise.calibrated_dark_level && self.calib.is_none() {
            lines.push(format!(
                "note: {} learned calibrated captures (dark level subtracted); without --calib \
the file's black level is taken as exact, and an error in it tints dark areas",
                self.model().display()
            ));
        }
        lines
    }
}
