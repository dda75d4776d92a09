//! The paper's sampling search (Algorithm 2), whole: on validation pairs,
//! the two-stage sampler's PSNR/SSIM for every candidate second time
//! t in {s, 2s, .., ns <= 1}, the best mean PSNR kept as the model's t2.
//!
//! For each pair, the first stage gives XZ = v(X0, T, 0) + X0 once (it does
//! not depend on t) and the second stage gives
//! XM = v(t XZ + (1 - t) X0, T, t) + X0 per candidate: the very functions
//! [`pgrf_nn::flow::sample::two_stage`] chains, so a grid of n times costs n + 1
//! network evaluations per pair (not 2n) and scores exactly what inference
//! will run at t2 = t. Scores are pgrf-eval's (ELD protocol by default).
//!
//! [`run`] is `pgrf search`'s recipe: from a weight file and a
//! [`SearchRequest`] it makes validation pairs like the model's training
//! pairs (its record's noise, the calibration given, clean RAWs, photos or
//! procedural scenes), measures ([`measure`], [`SearchOutcome`]) and writes
//! the chosen t2 into the weight file ([`store_t2`]) unless told not to,
//! after drawing PSNR against t. `pgrf search` is its flags
//! ([`flags::SearchArgs`], the `clap` feature), that call and printing
//! ([`Searched::table`], [`Searched::json`]).

use burn::tensor::{Tensor, TensorData};
use ndarray::{Array3, ArrayView3};
use pgrf_calib::mix::{MixError, MixSpec};
use pgrf_core::Progress;
use pgrf_eval::{evaluate, Protocol};
use pgrf_nn::arch::input_as_read;
use pgrf_nn::backend::{on_device, DeviceKind, OnBackend};
use pgrf_nn::condition::Conditioned;
use pgrf_nn::data::build::validation_source;
use pgrf_nn::data::source::Source;
use pgrf_nn::data::validation::ValSet;
use pgrf_nn::flow::sample::{first_stage, second_stage, two_stage, Velocity};
use pgrf_nn::ops::PgrfOps;
use pgrf_nn::weights::{self, WeightMeta};
use pgrf_nn::{NnError, Result};
use pgrf_noise::pair::RatioSpec;
use std::path::{Path, PathBuf};

#[cfg(feature = "clap")]
pub mod flags;
mod report;

/// The candidate times {s, 2s, .., ns} with ns <= 1 (1 included when s divides it).
pub(crate) fn grid(step: f64) -> Result<Vec<f64>> {
    if !(step.is_finite() && step > 0.0 && step <= 1.0) {
        return Err(NnError::BadSetting {
            flag: "--step",
            message: format!("--step must be in (0, 1], got {step}"),
        });
    }
    let n = (1.0 / step + 1e-9).floor() as usize;
    if n > 1000 {
        return Err(NnError::BadSetting {
            flag: "--step",
            message: format!("--step {step} gives {n} candidates; use at least 0.001"),
        });
    }
    Ok((1..=n).map(|i| i as f64 * step).collect())
}

/// Sample counts reported by the averaging study: powers of two and `k_max`.
pub(crate) fn reported_counts(k_max: usize) -> Vec<usize> {
    let mut v: Vec<usize> = std::iter::successors(Some(1usize), |k| Some(k * 2))
        .take_while(|k| *k < k_max)
        .collect();
    v.push(k_max.max(1));
    v
}

use pgrf_nn::infer::restorer::MAX_SAMPLES;

/// How to search.
#[derive(Clone, Debug)]
pub struct SearchOptions {
    /// Grid step s: candidates t in {s, 2s, .., ns <= 1}.
    pub step: f64,
    /// Also measure the mean of up to this many two-stage samples (different
    /// X0) at the best t, reported for K = 1, 2, 4, .., `samples`; 1: no
    /// averaging study (1 to 64).
    pub samples: usize,
    /// Seed of the extra start fields of the averaging study (sample 1 uses
    /// each pair's own X0).
    pub seed: u64,
    /// Where the network runs.
    pub device: DeviceKind,
    /// Whose CPU operations the network runs.
    pub kernels: pgrf_nn::ops::Kernels,
    /// How outputs are scored against the clean images.
    pub protocol: Protocol,
    /// The kept t2 is the smallest t whose mean PSNR is within this many dB
    /// of the curve's best ([`DEFAULT_TOLERANCE_DB`]; 0: the argmax).
    pub tolerance_db: f64,
}

/// Default of [`SearchOptions::tolerance_db`]. The curve is flat to a few
/// thousandths of a dB over most t (the built-in PGRF: 0.005 dB from 0.1
/// to 0.7, MODELS.md), while a larger t2 re-noises the first stage's
/// estimate more and the second stage then draws more of the field's
/// ring-shaped speckles (on the 550D chart at A7S2 ISO 1600 x100, 2 pixels
/// where the correction of the SPC's restoration passes 0.02 of white at
/// t2 = 0.1, 115 at 0.5; `crates/app/tests/artefacts.rs`); so among times
/// the validation cannot tell apart, the least re-noised wins.
pub const DEFAULT_TOLERANCE_DB: f64 = 0.01;

/// The largest tolerance `--tolerance` takes: beyond it the rule would
/// trade measured PSNR for the artefact it avoids.
pub const MAX_TOLERANCE_DB: f64 = 0.1;

impl Default for SearchOptions {
    /// Step 0.1, no averaging, seed 0, CPU with pgrf's operations, ELD
    /// protocol without illuminance correction.
    fn default() -> Self {
        SearchOptions {
            step: 0.1,
            samples: 1,
            seed: 0,
            device: DeviceKind::Cpu,
            kernels: pgrf_nn::ops::Kernels::Pgrf,
            protocol: Protocol::eld(false),
            tolerance_db: DEFAULT_TOLERANCE_DB,
        }
    }
}

impl SearchOptions {
    /// The candidate times, after checking the step and the sample count
    /// (callers may call it early to refuse bad options before costly work).
    pub fn times(&self) -> Result<Vec<f64>> {
        let times = grid(self.step)?;
        if !(0.0..=MAX_TOLERANCE_DB).contains(&self.tolerance_db) {
            return Err(NnError::BadSetting {
                flag: "--tolerance",
                message: format!(
                    "--tolerance must be from 0 to {MAX_TOLERANCE_DB} dB, got {}",
                    self.tolerance_db
                ),
            });
        }
        if self.samples == 0 || self.samples > MAX_SAMPLES {
            return Err(NnError::BadSetting {
                flag: "--samples",
                message: format!(
                    "--samples must be from 1 to {MAX_SAMPLES}, got {}",
                    self.samples
                ),
            });
        }
        Ok(times)
    }
}

/// What the search measured; every score is a mean over the pairs.
#[derive(Clone, Debug, PartialEq)]
pub struct SearchOutcome {
    /// (t, PSNR dB, SSIM) of the two-stage sampler at each candidate t.
    pub curve: Vec<(f64, f64, f64)>,
    /// Index into `curve` of the kept t: the smallest t within the options'
    /// tolerance of the best mean PSNR.
    pub best: usize,
    /// The best t: the model's t2.
    pub best_t2: f64,
    /// (PSNR, SSIM) of the first stage alone (one-step sampler).
    pub one_step: (f64, f64),
    /// (PSNR, SSIM) of the noisy input itself.
    pub input: (f64, f64),
    /// (K, PSNR, SSIM) of the mean of K samples at the best t, for
    /// K = 1, 2, 4, .., `samples`; just K = 1 (the curve's best point)
    /// without an averaging study.
    pub averaging: Vec<(usize, f64, f64)>,
}

/// Where the search's validation pairs come from.
#[derive(Clone, Debug, PartialEq)]
pub enum ValPairs {
    /// `pairs` crops of the clean RAW files, or of photos (unprocessed as
    /// the model's training run did it), in a folder or file.
    Files {
        /// The folder or file.
        path: PathBuf,
        /// How many pairs to draw.
        pairs: usize,
    },
    /// This many procedural scenes.
    Procedural(usize),
}

/// What `pgrf search` is asked: the model, its validation pairs, the noise
/// overrides and how to search.
#[derive(Clone, Debug)]
pub struct SearchRequest {
    /// The flow model's weight file; its t2 is rewritten unless `dry_run`.
    pub model: PathBuf,
    /// The validation pairs (None: refused, naming the flags).
    pub val: Option<ValPairs>,
    /// Side of the validation crops in packed pixels (at least 16).
    pub patch: usize,
    /// A fixed exposure ratio (default: drawn from the file's training range).
    pub ratio: Option<f32>,
    /// ISO of the synthetic noise (default: the file's, else ELD-sampled).
    pub iso: Option<u32>,
    /// The calibration file the model was trained with.
    pub calib: Option<PathBuf>,
    /// Measure only, leaving the weight file as it is.
    pub dry_run: bool,
    /// The PNG plot of PSNR against t (its folder is checked first).
    pub plot: PathBuf,
    /// Grid, averaging study, seed (of the pairs too), device, protocol.
    pub options: SearchOptions,
    /// darktable's noiseprofiles.json for a model trained on a `darktable:`
    /// profile (None: darktable's install is searched).
    pub darktable: Option<PathBuf>,
}

/// What [`run`] measured and on what, for printing.
#[derive(Clone, Debug)]
pub struct Searched {
    /// The scores.
    pub outcome: SearchOutcome,
    /// The model's record (before t2 was written).
    pub meta: WeightMeta,
    /// The number of validation pairs.
    pub pairs: usize,
    /// The pairs, in words ("2 procedural scenes", "8 crops of ...").
    pub what: String,
    /// The exposure ratios of the pairs.
    pub ratio: RatioSpec,
    /// The fixed ISO of the noise, if any.
    pub iso: Option<u32>,
    /// Otherwise the ISO range the gain was drawn from, if narrowed.
    pub iso_range: Option<(u32, u32)>,
    /// The noise's profiles, in words.
    pub profiles: String,
    /// Whether t2 was written into the weight file.
    pub written: bool,
}

/// `pgrf search`'s recipe (Algorithm 2, whole): checks the request and the
/// model (a flow model), makes the validation pairs as the model's training
/// pairs were made (its record's profile or mix, ISO or ISO range, ratios;
/// `iso` and `ratio` override; `calib` applied; photos unprocessed as its
/// recorded configuration says; `warn` hears each file skipped), refuses
/// pairs that would not fit in memory, measures ([`measure`]), draws the
/// plot and, unless `dry_run`, stores the best t2 ([`store_t2`]).
pub fn run(req: &SearchRequest, progress: &dyn Progress, warn: &dyn Fn(&str)) -> Result<Searched> {
    let meta = check_request(req)?;
    let noise = pairs_noise(req, &meta)?;
    let (source, count, what) = validation_data(req, &meta, warn)?;
    let p = req.patch;
    let need = pgrf_nn::infer::memory::tile_bytes(&meta.arch, p, p) + ValSet::bytes(p, count);
    pgrf_core::mem::check_fits(&format!("--patch {p} with {count} pairs"), need)
        .map_err(|e| NnError::TooLarge(format!("{e}; give a smaller --patch or fewer pairs")))?;
    let val = ValSet::build(&source, &noise.built.mix, p, count, req.options.seed)?;
    let outcome = measure(&req.model, &val, &req.options, progress)?;
    report::write_plot(req, &outcome)?;
    if !req.dry_run {
        store_t2(&req.model, outcome.best_t2)?;
    }
    Ok(Searched {
        outcome,
        meta,
        pairs: count,
        what,
        ratio: noise.ratio,
        iso: noise.iso,
        iso_range: noise.iso_range,
        profiles: noise.built.mix.describe(),
        written: !req.dry_run,
    })
}

/// The request's settings and its model checked before any costly work
/// (bad --step, --samples or --plot first; then the model must be a flow
/// model, the patch at least 16, the device there): the model's record.
fn check_request(req: &SearchRequest) -> Result<WeightMeta> {
    req.options.times()?;
    pgrf_core::paths::require_parent_dir(&req.plot).map_err(|e| NnError::BadSetting {
        flag: "--plot",
        message: format!("--plot: {e}"),
    })?;
    let meta = weights::read_meta(&req.model).map_err(|e| NnError::Input {
        flag: "--model",
        path: req.model.clone(),
        cause: Box::new(e),
    })?;
    if !meta.arch.sampled() {
        return Err(NnError::WrongArchitecture {
            path: req.model.clone(),
            message: format!(
                "--model {}: holds an {}; the sampling search is for PGRF flow models",
                req.model.display(),
                meta.arch.describe()
            ),
        });
    }
    if req.patch < 16 {
        return Err(NnError::BadSetting {
            flag: "--patch",
            message: format!(
                "--patch must be at least 16 packed pixels, got {}",
                req.patch
            ),
        });
    }
    req.options
        .device
        .check_available()
        .map_err(NnError::Device)?;
    Ok(meta)
}

/// The validation pairs' noise and the conditions it was drawn at.
struct PairsNoise {
    built: pgrf_calib::mix::CalibratedMix,
    ratio: RatioSpec,
    iso: Option<u32>,
    iso_range: Option<(u32, u32)>,
}

/// The pairs' noise as the model's training drew it (its record's profile
/// or mix, ISO or ISO range, ratio draw and calibrated share; the
/// request's `iso` and `ratio` override; `calib` applied).
fn pairs_noise(req: &SearchRequest, meta: &WeightMeta) -> Result<PairsNoise> {
    let noise = &meta.noise;
    let trained = meta.training.as_ref().and_then(|t| t.config.as_ref());
    let ratio = match req.ratio {
        Some(r) => {
            RatioSpec::Fixed(pgrf_noise::pair::ratio_in_range("--ratio", r).map_err(|e| {
                NnError::BadSetting {
                    flag: "--ratio",
                    message: e.to_string(),
                }
            })?)
        }
        None => trained
            .map_or(pgrf_nn::RatioDraw::Uniform, |c| c.ratio_draw)
            .spec(noise.ratio[0], noise.ratio[1]),
    };
    let (iso, iso_range) = match req.iso {
        Some(v) => (Some(v), None),
        None => (noise.iso, noise.iso_range.map(|[lo, hi]| (lo, hi))),
    };
    let profile = noise.profile.clone().unwrap_or_else(|| "sony-a7s2".into());
    let built = pgrf_calib::mix::build(&MixSpec {
        profile: &profile,
        model: noise.model,
        iso,
        iso_range,
        ratio,
        calibrated_dark_level: noise.calibrated_dark_level,
        calibrated_share: trained.map_or(0.0, |c| c.calibrated_share),
        calibration: req.calib.as_deref(),
        noise_bank: trained.is_some_and(|c| c.noise_bank) && req.calib.is_some(),
        darktable: req.darktable.as_deref(),
    })
    .map_err(|e| match e {
        MixError::Profile(e) => NnError::Input {
            flag: "--model",
            path: req.model.clone(),
            cause: Box::new(NnError::Config(format!("its noise record: {e}"))),
        },
        MixError::CalibrationWithMix { path, mix } => NnError::BadSetting {
            flag: "--calib",
            message: format!(
                "--calib {}: the model was trained on a mix of profiles ({mix}); a calibration describes one sensor",
                path.display()
            ),
        },
        e => NnError::Caller(Box::new(e)),
    })?;
    Ok(PairsNoise {
        built,
        ratio,
        iso,
        iso_range,
    })
}

/// Where the validation crops come from, how many, and that in words
/// (photos unprocessed as the model's training run did it; `warn` hears
/// each file skipped).
fn validation_data(
    req: &SearchRequest,
    meta: &WeightMeta,
    warn: &dyn Fn(&str),
) -> Result<(Source, usize, String)> {
    let (source, count, what) = match &req.val {
        Some(ValPairs::Files { path, pairs }) => {
            let config = (meta.training.as_ref())
                .and_then(|t| t.config.clone())
                .unwrap_or_default();
            let (src, skipped) = validation_source(&config, "--val", path, req.patch)?;
            for w in skipped {
                warn(&w);
            }
            let what = format!("{pairs} crops of {}", src.describe());
            (src, *pairs, what)
        }
        Some(ValPairs::Procedural(n)) => (Source::Procedural, *n, format!("{n} procedural scenes")),
        None => {
            return Err(NnError::BadSetting {
                flag: "--val",
                message:
                    "give validation data: --val DIR (clean RAW files or photos) or --procedural N"
                        .into(),
            })
        }
    };
    if count == 0 {
        return Err(NnError::BadSetting {
            flag: "--pairs",
            message: "no validation pairs: --pairs/--procedural must be at least 1".into(),
        });
    }
    Ok((source, count, what))
}

/// Algorithm 2 with the flow model in the weight file `model`: scores the
/// two-stage sampler at every candidate t on `pairs` (their own X0), the
/// one-step sampler and the input, keeps the best t, and runs the
/// averaging study when `opts.samples > 1`. Reports network evaluations to
/// `progress` (one stage of `pairs x (n + 1 [+ samples])` units).
/// Leaves the weight file as it is: see [`store_t2`].
pub fn measure(
    model: &Path,
    pairs: &ValSet,
    opts: &SearchOptions,
    progress: &dyn Progress,
) -> Result<SearchOutcome> {
    opts.times()?;
    struct Job<'a> {
        model: &'a Path,
        pairs: &'a ValSet,
        opts: &'a SearchOptions,
        progress: &'a dyn Progress,
    }
    impl OnBackend for Job<'_> {
        type Output = SearchOutcome;
        fn run<B: PgrfOps>(self, device: B::Device) -> Result<SearchOutcome> {
            run_on::<B>(self.model, &device, self.pairs, self.opts, self.progress)
        }
    }
    let kernels = opts.kernels;
    pgrf_nn::ops::with_kernels(kernels, || {
        on_device(
            opts.device,
            Job {
                model,
                pairs,
                opts,
                progress,
            },
        )
    })
}

fn run_on<B: PgrfOps>(
    model: &Path,
    device: &B::Device,
    pairs: &ValSet,
    opts: &SearchOptions,
    progress: &dyn Progress,
) -> Result<SearchOutcome> {
    let (net, _) = pgrf_nn::model::load_flow::<B>(model, device)?;
    search_with(&net, device, pairs, opts, progress)
}

/// [`measure`] with a network already in memory (any velocity field `net` on
/// `device`): the same measurement, for callers that hold the model and
/// for tests.
pub(crate) fn search_with<B: PgrfOps>(
    net: &impl Velocity<B>,
    device: &B::Device,
    pairs: &ValSet,
    opts: &SearchOptions,
    progress: &dyn Progress,
) -> Result<SearchOutcome> {
    let times = opts.times()?;
    let (patch, list) = (pairs.patch, pairs.pairs.as_slice());
    let count = list.len();
    if count == 0 {
        return Err(NnError::BadSetting {
            flag: "--pairs",
            message: "no validation pairs: --pairs/--procedural must be at least 1".into(),
        });
    }
    let protocol = &opts.protocol;
    let n_t = times.len();
    let mut input = (0.0f64, 0.0f64);
    for p in list {
        let s =
            evaluate(view(&p.noisy, patch)?, view(&p.clean, patch)?, protocol).map_err(metric)?;
        input.0 += s.psnr / count as f64;
        input.1 += s.ssim / count as f64;
    }
    let extra = if opts.samples > 1 { opts.samples } else { 0 };
    progress.start((count * (n_t + 1 + extra)) as u64, "network evaluations");

    let mut psnr = vec![0.0f64; n_t];
    let mut ssim = vec![0.0f64; n_t];
    let mut one = (0.0f64, 0.0f64);
    let tensor = |v: &[f32]| to_tensor::<B>(v, patch, device);
    for pair in list {
        let clean = view(&pair.clean, patch)?;
        let score = |out: Tensor<B, 4>, acc: (&mut f64, &mut f64)| -> Result<()> {
            let s = evaluate(to_array(out, patch)?.view(), clean, protocol).map_err(metric)?;
            *acc.0 += s.psnr / count as f64;
            *acc.1 += s.ssim / count as f64;
            Ok(())
        };
        let raw = tensor(&pair.noisy)?;
        let noisy = input_as_read(net.keeps_below_black(), raw.clone());
        let c = Conditioned::new(net.conditioning(), noisy, &[pair.level]);
        let cond = net.condition(&c, raw, &[pair.level]);
        let x0 = tensor(&pair.x0)?;
        let xz = first_stage(net, cond.clone(), x0.clone());
        score(c.input_units_of(xz.clone()), (&mut one.0, &mut one.1))?;
        progress.advance(1);
        for (k, &t) in times.iter().enumerate() {
            let xm = second_stage(net, cond.clone(), x0.clone(), xz.clone(), t as f32);
            score(c.input_units_of(xm), (&mut psnr[k], &mut ssim[k]))?;
            progress.advance(1);
        }
    }
    let best = best_index(&psnr, opts.tolerance_db);
    let best_t2 = times[best];
    let averaging = if opts.samples > 1 {
        average(net, device, pairs, opts, best_t2, progress)?
    } else {
        vec![(1, psnr[best], ssim[best])]
    };
    progress.finish();
    Ok(SearchOutcome {
        curve: (0..n_t).map(|k| (times[k], psnr[k], ssim[k])).collect(),
        best,
        best_t2,
        one_step: one,
        input,
        averaging,
    })
}

/// The first index (the smallest t) whose value is within `tolerance` of
/// the largest; with 0 the argmax, ties to the first.
fn best_index(psnr: &[f64], tolerance: f64) -> usize {
    let max = psnr.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    psnr.iter().position(|&v| v >= max - tolerance).unwrap_or(0)
}

/// Writes `t2` into the weight file `model` (its JSON record only, an
/// atomic rewrite; the tensors stay byte for byte), so that inference's
/// two-stage sampler uses it. Returns the updated record.
pub fn store_t2(model: &Path, t2: f64) -> Result<WeightMeta> {
    weights::update_meta(model, |m| m.t2 = Some(t2 as f32))
}

/// What averaging K two-stage samples (different X0) at `t2` buys: for each
/// pair the running mean of samples 1..=K, scored at K = 1, 2, 4, .. and
/// `opts.samples`. Sample 1 uses the pair's own X0; the others draw fresh
/// start noise from `opts.seed`.
fn average<B: PgrfOps>(
    net: &impl Velocity<B>,
    device: &B::Device,
    pairs: &ValSet,
    opts: &SearchOptions,
    t2: f64,
    progress: &dyn Progress,
) -> Result<Vec<(usize, f64, f64)>> {
    let (patch, list) = (pairs.patch, pairs.pairs.as_slice());
    let count = list.len();
    let k_max = opts.samples;
    let report = reported_counts(k_max);
    let mut out: Vec<(usize, f64, f64)> = report.iter().map(|&k| (k, 0.0, 0.0)).collect();
    for (i, pair) in list.iter().enumerate() {
        let clean = view(&pair.clean, patch)?;
        let raw = to_tensor::<B>(&pair.noisy, patch, device)?;
        let noisy = input_as_read(net.keeps_below_black(), raw.clone());
        let c = Conditioned::new(net.conditioning(), noisy, &[pair.level]);
        let cond = net.condition(&c, raw, &[pair.level]);
        let mut sum: Option<Tensor<B, 4>> = None;
        for k in 1..=k_max.max(1) {
            let x0 = if k == 1 {
                to_tensor::<B>(&pair.x0, patch, device)?
            } else {
                let field = pgrf_nn::infer::start::start_noise(
                    opts.seed ^ ((i as u64) << 20),
                    k as u64,
                    4,
                    patch,
                    patch,
                );
                to_tensor::<B>(field.as_slice().expect("standard layout"), patch, device)?
            };
            let y = c.input_units_of(two_stage(net, cond.clone(), x0, t2 as f32));
            sum = Some(match sum {
                None => y,
                Some(s) => s + y,
            });
            progress.advance(1);
            if let Some(slot) = out.iter_mut().find(|(kk, _, _)| *kk == k) {
                let mean = sum.clone().expect("k >= 1") / k as f32;
                let s = evaluate(to_array(mean, patch)?.view(), clean, &opts.protocol)
                    .map_err(metric)?;
                slot.1 += s.psnr / count as f64;
                slot.2 += s.ssim / count as f64;
            }
        }
    }
    Ok(out)
}

fn metric(e: pgrf_eval::MetricError) -> NnError {
    NnError::Caller(Box::new(e))
}

fn view(v: &[f32], patch: usize) -> Result<ArrayView3<'_, f32>> {
    ArrayView3::from_shape((4, patch, patch), v)
        .map_err(|_| NnError::SizeMismatch("validation pair of the wrong size".into()))
}

fn to_tensor<B: PgrfOps>(v: &[f32], patch: usize, device: &B::Device) -> Result<Tensor<B, 4>> {
    if v.len() != 4 * patch * patch {
        return Err(NnError::SizeMismatch(
            "validation pair of the wrong size".into(),
        ));
    }
    Ok(Tensor::from_data(
        TensorData::new(v.to_vec(), [1, 4, patch, patch]),
        device,
    ))
}

fn to_array<B: PgrfOps>(t: Tensor<B, 4>, patch: usize) -> Result<Array3<f32>> {
    let v: Vec<f32> = t
        .into_data()
        .to_vec()
        .map_err(|e| NnError::Invalid(format!("reading the network output: {e:?}")))?;
    Array3::from_shape_vec((4, patch, patch), v)
        .map_err(|e| NnError::SizeMismatch(format!("network output shape: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use pgrf_nn::backend::Cpu;

    #[test]
    fn averaging_reports_powers_of_two_and_the_maximum() {
        assert_eq!(reported_counts(1), vec![1]);
        assert_eq!(reported_counts(4), vec![1, 2, 4]);
        assert_eq!(reported_counts(6), vec![1, 2, 4, 6]);
    }

    #[test]
    fn the_grid_is_s_to_ns() {
        let g = grid(0.1).unwrap();
        assert_eq!(g.len(), 10);
        assert!((g[0] - 0.1).abs() < 1e-12 && (g[9] - 1.0).abs() < 1e-12);
        assert_eq!(grid(0.3).unwrap().len(), 3);
        assert_eq!(grid(1.0).unwrap(), vec![1.0]);
        assert!(grid(0.0).is_err());
        assert!(grid(1.5).is_err());
        assert!(grid(f64::NAN).is_err());
    }

    #[test]
    fn ties_go_to_the_smaller_t() {
        assert_eq!(best_index(&[1.0, 3.0, 3.0, 2.0], 0.0), 1);
        assert_eq!(best_index(&[5.0], 0.0), 0);
        // Within the tolerance of the best, the smaller t wins; beyond it not.
        assert_eq!(best_index(&[2.995, 3.0, 2.0], 0.01), 0);
        assert_eq!(best_index(&[2.98, 2.995, 3.0], 0.01), 1);
        assert_eq!(best_index(&[2.98, 2.995, 3.0], 0.0), 2);
    }

    /// A small SR3 field with seeded (random, not trained) weights and two
    /// procedural validation pairs: the second stage depends on t.
    fn fixture() -> (pgrf_nn::arch::sr3::Sr3Unet<Cpu>, ValSet) {
        use pgrf_nn::arch::sr3::Sr3Config;
        use pgrf_nn::data::source::Source;
        use pgrf_noise::pair::PairSpec;
        use pgrf_noise::{CameraProfile, ModelKind};
        let dev = Default::default();
        let net = pgrf_nn::seeded::seeded::<Cpu, _>(&dev, 5, || {
            Sr3Config::new()
                .with_inner_channels(8)
                .with_channel_mults(vec![1, 2])
                .with_res_blocks(1)
                .with_attn_levels(vec![])
                .with_norm_groups(4)
                .init::<Cpu>(&dev)
                .map(pgrf_nn::seeded::materialise)
        })
        .unwrap();
        let mut spec = PairSpec::new(
            CameraProfile::built_in("sony-a7s2").unwrap(),
            ModelKind::Pgrf,
        );
        spec.iso = Some(1600);
        let val = ValSet::build(&Source::Procedural, &spec.into(), 16, 2, 4).unwrap();
        (net, val)
    }

    /// Mean (PSNR, SSIM) over the pairs of `f(cond, x0)`, the condition as
    /// the fixture's network reads it (clamped at 0: it does not keep values
    /// below black).
    fn mean_scores(
        val: &ValSet,
        f: impl Fn(Tensor<Cpu, 4>, Tensor<Cpu, 4>) -> Tensor<Cpu, 4>,
    ) -> (f64, f64) {
        let dev = Default::default();
        let p = val.patch;
        let n = val.pairs.len() as f64;
        let mut acc = (0.0, 0.0);
        for pair in &val.pairs {
            let out = f(
                to_tensor::<Cpu>(&pair.noisy, p, &dev)
                    .unwrap()
                    .clamp_min(0.0),
                to_tensor::<Cpu>(&pair.x0, p, &dev).unwrap(),
            );
            let s = evaluate(
                to_array(out, p).unwrap().view(),
                view(&pair.clean, p).unwrap(),
                &Protocol::eld(false),
            )
            .unwrap();
            acc.0 += s.psnr / n;
            acc.1 += s.ssim / n;
        }
        acc
    }

    /// The search's score at each t is the two-stage sampler's at t2 = t
    /// (the same pairs, the same X0), its one-step score the one-step
    /// sampler's, and the best t the argmax of the curve.
    #[test]
    fn the_search_scores_the_two_stage_sampler_at_each_t() {
        use pgrf_nn::flow::sample::one_step;
        let (net, val) = fixture();
        let opts = SearchOptions {
            step: 0.25,
            ..Default::default()
        };
        let got = search_with(
            &net,
            &Default::default(),
            &val,
            &opts,
            &pgrf_core::NoProgress,
        )
        .unwrap();
        assert_eq!(got.curve.len(), 4);
        for &(t, psnr, ssim) in &got.curve {
            let (p, s) = mean_scores(&val, |c, x0| two_stage(&net, c, x0, t as f32));
            assert!(
                (p - psnr).abs() < 1e-6,
                "t {t}: sampler {p} vs search {psnr}"
            );
            assert!(
                (s - ssim).abs() < 1e-6,
                "t {t}: sampler {s} vs search {ssim}"
            );
        }
        let (p, s) = mean_scores(&val, |c, x0| one_step(&net, c, x0));
        assert!((p - got.one_step.0).abs() < 1e-6 && (s - got.one_step.1).abs() < 1e-6);
        // The curve is not flat (t matters), and the kept t is the smallest
        // within the default tolerance of its best.
        let psnr: Vec<f64> = got.curve.iter().map(|c| c.1).collect();
        assert!(psnr.iter().any(|&p| p != psnr[0]), "{psnr:?}");
        assert_eq!(got.best, best_index(&psnr, DEFAULT_TOLERANCE_DB));
        assert_eq!(got.best_t2, got.curve[got.best].0);
        assert_eq!(
            got.averaging,
            vec![(1, psnr[got.best], got.curve[got.best].2)]
        );
        // The input's score is the noisy condition's own.
        let (p, _) = mean_scores(&val, |c, _| c);
        assert!((p - got.input.0).abs() < 1e-6);
    }

    /// The averaging study's K = 1 is the curve's best point (each pair's
    /// own X0); K = 2 averages in a second start field and differs.
    #[test]
    fn averaging_starts_from_the_best_point() {
        let (net, val) = fixture();
        let opts = SearchOptions {
            step: 0.5,
            samples: 2,
            ..Default::default()
        };
        struct Count(std::sync::atomic::AtomicU64);
        impl Progress for Count {
            fn advance(&self, n: u64) {
                self.0.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
            }
        }
        let count = Count(Default::default());
        let got = search_with(&net, &Default::default(), &val, &opts, &count).unwrap();
        // 2 pairs x (1 one-step + 2 times + 2 samples).
        assert_eq!(count.0.into_inner(), 10);
        let best = got.curve[got.best];
        assert_eq!(got.averaging.len(), 2);
        assert_eq!(got.averaging[0].0, 1);
        assert!((got.averaging[0].1 - best.1).abs() < 1e-9, "{got:?}");
        assert_eq!(got.averaging[1].0, 2);
        assert_ne!(got.averaging[1].1, got.averaging[0].1);
    }

    #[test]
    fn bad_options_are_refused() {
        let (net, val) = fixture();
        for opts in [
            SearchOptions {
                step: 0.0,
                ..Default::default()
            },
            SearchOptions {
                samples: 0,
                ..Default::default()
            },
            SearchOptions {
                samples: MAX_SAMPLES + 1,
                ..Default::default()
            },
            SearchOptions {
                tolerance_db: -0.01,
                ..Default::default()
            },
            SearchOptions {
                tolerance_db: MAX_TOLERANCE_DB * 1.5,
                ..Default::default()
            },
            SearchOptions {
                tolerance_db: f64::NAN,
                ..Default::default()
            },
        ] {
            assert!(search_with(
                &net,
                &Default::default(),
                &val,
                &opts,
                &pgrf_core::NoProgress
            )
            .is_err());
        }
        let empty = ValSet {
            patch: 16,
            pairs: vec![],
        };
        let err = search_with(
            &net,
            &Default::default(),
            &empty,
            &SearchOptions::default(),
            &pgrf_core::NoProgress,
        )
        .unwrap_err();
        assert!(err.to_string().contains("at least 1"), "{err}");
    }
}
