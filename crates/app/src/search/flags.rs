//! `pgrf search`'s flags (the `clap` feature) and the request they make:
//! kept beside the recipe, so a new option is added in one crate.

use super::{SearchOptions, SearchRequest, ValPairs};
use pgrf_eval::Protocol;
use pgrf_nn::backend::DeviceKind;
use std::path::PathBuf;

/// `pgrf search`'s flags.
#[derive(clap::Args, Debug)]
pub struct SearchArgs {
    /// Flow model weight file (from `pgrf train flow`); its t2 is rewritten.
    #[arg(long, short = 'm')]
    pub model: PathBuf,
    /// Folder of clean RAW files, or of photos (unprocessed into the camera's
    /// RAW space as the model's training run did it), to make validation pairs from.
    #[arg(long, conflicts_with = "procedural")]
    pub val: Option<PathBuf>,
    /// Or: this many procedural scenes as validation pairs.
    #[arg(long)]
    pub procedural: Option<usize>,
    /// Number of validation pairs drawn from --val (crops of its files).
    #[arg(long, default_value_t = 8)]
    pub pairs: usize,
    /// Grid step s: t in {s, 2s, .., ns <= 1}.
    #[arg(long, default_value_t = 0.1)]
    pub step: f64,
    /// Side of the validation crops in packed pixels.
    #[arg(long, default_value_t = 256)]
    pub patch: usize,
    /// Exposure ratio of the pairs (default: drawn from the file's training range).
    #[arg(long)]
    pub ratio: Option<f32>,
    /// ISO of the synthetic noise (default: the file's, else ELD-sampled parameters).
    #[arg(long)]
    pub iso: Option<u32>,
    /// Calibration file the model was trained with (per-pixel noise maps).
    #[arg(long)]
    pub calib: Option<PathBuf>,
    /// Seed of the validation pairs and their start noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// PNG plot of PSNR against t (default: next to the model, `.search.png`).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Also measure what averaging up to K samples (different start noise)
    /// at the best t buys, reported for K = 1, 2, 4, .., K.
    #[arg(long, default_value_t = 1)]
    pub samples: usize,
    /// Measure and print, but leave the weight file as it is.
    #[arg(long)]
    pub dry_run: bool,
    /// cpu, or cuda (needs a build with `--features cuda`).
    #[arg(long, default_value = "cpu")]
    pub device: DeviceKind,
    /// One JSON line on stdout instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Keep the smallest t whose mean PSNR is within this many dB of the
    /// best (0 to 0.1; 0: the argmax): where the curve is flat, a smaller
    /// t2 re-noises less and shows fewer ring-shaped speckles.
    #[arg(long, default_value_t = super::DEFAULT_TOLERANCE_DB)]
    pub tolerance: f64,
}

impl SearchArgs {
    /// The flags as a search request run on `kernels`' operations (the ELD
    /// protocol's scores; the plot next to the model unless named).
    pub fn request(&self, kernels: pgrf_nn::ops::Kernels) -> SearchRequest {
        let val = match (&self.val, self.procedural) {
            (Some(path), _) => Some(ValPairs::Files {
                path: path.clone(),
                pairs: self.pairs,
            }),
            (None, Some(n)) => Some(ValPairs::Procedural(n)),
            (None, None) => None,
        };
        SearchRequest {
            model: self.model.clone(),
            val,
            patch: self.patch,
            ratio: self.ratio,
            iso: self.iso,
            calib: self.calib.clone(),
            dry_run: self.dry_run,
            plot: (self.plot.clone()).unwrap_or_else(|| self.model.with_extension("search.png")),
            options: SearchOptions {
                step: self.step,
                samples: self.samples,
                seed: self.seed,
                device: self.device,
                kernels,
                protocol: Protocol::eld(false),
                tolerance_db: self.tolerance,
            },
            // The caller's (the command line's global --darktable-profiles).
            darktable: None,
        }
    }
}
