//! Training, whole: [`run`] turns a [`TrainConfig`] into a trained weight
//! file (`pgrf train` is that call plus printing). Before the loop it checks
//! the device, the network and the memory a step needs, builds the pairs'
//! noise (profiles and calibration, `pgrf_calib::mix`), the clean sources
//! and the validation pairs; the loop shared by both networks takes batches
//! from the worker-thread loader, runs Adam with a learning-rate schedule,
//! validation PSNR, logs and checkpoints, and stops cleanly on request.
//! Backend-generic: the device setting picks Flex on the CPU or CUDA.

use crate::arch::{Architecture, Net, StartAdapted};
use crate::backend::{on_train_device, OnTrainBackend};
use crate::checkpoint::{self, CheckpointState};
use crate::config::{Method, TrainConfig, TrainOutputs};
use crate::data::validation::{psnr, ValSet};
use crate::data::{Batch, Loader, SampleSpec, Source};
use crate::ema::Ema;
use crate::error::{NnError, Result};
use crate::ops::adam::PgrfAdam;
use crate::ops::{PgrfAutodiff, PgrfOps};
use crate::weights::{NoiseSource, StartedFrom, TrainingSummary, WeightMeta};
use burn::module::{AutodiffModule, Module};
use burn::optim::adaptor::OptimizerAdaptor;
use burn::optim::grad_clipping::GradientClippingConfig;
use burn::optim::{GradientsParams, Optimizer};
use burn::record::{BinBytesRecorder, FullPrecisionSettings, Recorder};
use burn::tensor::{ElementConversion, Tensor, TensorData};
use pgrf_core::Progress;
use pgrf_noise::mix::PairMix;
use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// How a run ended.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// Step the run started at (0, or the checkpoint's step on resume).
    pub start_step: u64,
    /// Steps completed when it ended (`steps`, or fewer when stopped).
    pub end_step: u64,
    /// Loss of every step run in this call, in order.
    pub losses: Vec<f32>,
    /// Loss of the last step (NaN if no step ran).
    pub final_loss: f32,
    /// Final validation PSNR in dB on the held-out pairs (the last one
    /// measured when stopped early); None without validation.
    pub val_psnr: Option<f32>,
    /// PSNR of the (amplified, clamped) noisy input on the validation pairs.
    pub val_input_psnr: Option<f32>,
    /// Wall-clock seconds of this call's training.
    pub seconds: f64,
    /// Training crops per second in this call.
    pub images_per_s: f64,
    /// Stopped by the `stop` flag before `steps`.
    pub interrupted: bool,
    /// A resumed run whose checkpoint had already reached `steps`, with the
    /// weight file it wrote then: nothing was trained or written.
    pub already_finished: bool,
}

/// A finished (or stopped) run: how it ended and what it wrote.
#[derive(Clone, Debug)]
pub struct Trained {
    /// How the run ended.
    pub outcome: Outcome,
    /// The method trained.
    pub method: Method,
    /// The weight file, checkpoint and log written.
    pub outputs: TrainOutputs,
}

/// `pgrf train`'s recipe: train `method`'s network as `config` says
/// (already merged and checked, [`TrainConfig::check_for`]), from scratch or,
/// with `resume`, from the checkpoint. Before any step: the checkpoint a
/// resumed run needs (first, before any costly work), the device, the
/// network (and `init`'s weights) and the memory a step needs are checked,
/// the pairs' noise is built by `noise`, the clean sources are opened (`warn` hears each
/// file left out), the validation pairs are made, and one line saying what
/// will be trained goes to `progress` as a note. `progress` hears one unit
/// per step; setting `stop` ends the run cleanly after the current step
/// (checkpoint and weight file written, [`Outcome::interrupted`]).
pub fn run(
    config: &TrainConfig,
    method: Method,
    resume: bool,
    noise: NoiseBuilder,
    progress: &dyn Progress,
    stop: &AtomicBool,
    warn: &dyn Fn(&str),
) -> Result<Trained> {
    crate::ops::with_kernels(config.kernels, || {
        run_with(config, method, resume, noise, progress, stop, warn)
    })
}

/// [`run`] on the calling thread, its operations chosen.
fn run_with(
    config: &TrainConfig,
    method: Method,
    resume: bool,
    noise: NoiseBuilder,
    progress: &dyn Progress,
    stop: &AtomicBool,
    warn: &dyn Fn(&str),
) -> Result<Trained> {
    let c = config;
    let outputs = c.outputs()?;
    check_before_work(c, &outputs, resume)?;
    let arch = c.architecture(method)?;
    if resume {
        let state = checkpoint::load(&outputs.checkpoint)?.state;
        check_resumable(&state, &arch, c, &outputs.checkpoint)?;
        if let Some(outcome) = finished(&state, c, &outputs) {
            return Ok(Trained {
                outcome,
                method,
                outputs,
            });
        }
    }
    c.device.check_available().map_err(NnError::Device)?;
    if let Some(init) = &c.init {
        crate::weights::require_arch(init, &arch)?;
    }
    check_memory(c, &arch)?;
    let iso_range = c.iso_range()?;
    let (lo, hi) = (c.ratio_min, c.ratio_max);
    let built = noise(c, iso_range)?;
    let sources = crate::data::build::sources(c)?;
    for w in &sources.warnings {
        warn(w);
    }
    let mix = Arc::new(built.mix);
    let val = (c.val_pairs > 0)
        .then(|| ValSet::build(&sources.val, &mix, c.val_patch(), c.val_pairs, c.seed))
        .transpose()?;
    let noise = NoiseSource {
        profile: Some(c.profile.clone()),
        calibration: built.calibration,
        model: c.noise,
        iso: c.iso,
        iso_range: iso_range.map(|(a, b)| [a, b]),
        ratio: [lo, hi],
        calibrated_dark_level: c.calibrated_dark_level,
    };
    progress.note(&header(c, &arch, &sources.train, &mix, &noise));
    let job = Job {
        config: c,
        arch,
        outputs,
        resume,
        noise,
        source: Arc::new(sources.train),
        mix,
        val: val.as_ref(),
        progress,
        stop,
    };
    let outputs = job.outputs.clone();
    let outcome = on_train_device(c.device, job)?;
    Ok(Trained {
        outcome,
        method,
        outputs,
    })
}

/// What is refused before any work: a run of no step without `init`, and
/// a resume without its checkpoint.
fn check_before_work(c: &TrainConfig, outputs: &TrainOutputs, resume: bool) -> Result<()> {
    if c.steps == 0 && c.init.is_none() {
        // Random weights recorded as a trained model: never what is wanted.
        // With --init a run of no step copies that file's weights and adds
        // up its history (its loss is NaN, null in the record, which reads
        // back as NaN).
        return Err(NnError::BadSetting {
            flag: "--steps",
            message: "--steps 0 trains nothing: give --steps 1 or more (or --init FILE, whose weights --steps 0 copies)".into(),
        });
    }
    if resume && !outputs.checkpoint.exists() {
        return Err(NnError::BadSetting {
            flag: "--resume",
            message: format!(
                "--resume: no checkpoint at {}",
                outputs.checkpoint.display()
            ),
        });
    }
    Ok(())
}

/// The noise a run's pairs are drawn with: one profile per capture, and the
/// identity of the calibration applied, for the weight file's record.
pub struct PairsNoise {
    /// The pairs' noise.
    pub mix: PairMix,
    /// The calibration's identity, when one was applied.
    pub calibration: Option<String>,
}

/// How a run builds its pairs' noise from its configuration and ISO range
/// ([`run`] calls it after its checks): `pgrf train`'s applies `--calib`
/// (`pgrf_app::train`); [`profiles_only`] is the noise without one.
pub type NoiseBuilder<'a> = &'a dyn Fn(&TrainConfig, Option<(u32, u32)>) -> Result<PairsNoise>;

/// The pairs' noise from the configuration's profiles alone; a
/// configuration naming a calibration is refused (the application applies
/// it: `pgrf_app::train`).
pub fn profiles_only(c: &TrainConfig, iso_range: Option<(u32, u32)>) -> Result<PairsNoise> {
    if let Some(p) = &c.calib {
        return Err(NnError::BadSetting {
            flag: "--calib",
            message: format!(
                "--calib {}: this run builds its noise from profiles only",
                p.display()
            ),
        });
    }
    let ratio = c.ratio_draw.spec(c.ratio_min, c.ratio_max);
    let darktable = c.darktable_profiles.as_deref();
    let mut mix =
        PairMix::build(&c.profile, c.noise, c.iso, iso_range, ratio, darktable).map_err(|e| {
            NnError::BadSetting {
                flag: "--profile",
                message: format!("--profile: {e}"),
            }
        })?;
    mix.set_calibrated_dark_level(c.calibrated_dark_level);
    mix.set_calibrated_share(c.calibrated_share);
    Ok(PairsNoise {
        mix,
        calibration: None,
    })
}

/// Refuse to resume from a checkpoint of another network or other settings,
/// or one past the run's `--steps` (its weights would be recorded as a run
/// of more steps than asked for).
fn check_resumable(
    st: &CheckpointState,
    arch: &Architecture,
    s: &TrainConfig,
    path: &std::path::Path,
) -> Result<()> {
    let arch_json = serde_json::to_value(arch).map_err(|e| NnError::Invalid(e.to_string()))?;
    if st.task != arch.method() || st.arch != arch_json {
        return Err(NnError::WrongArchitecture {
            path: path.to_path_buf(),
            message: format!(
                "{}: checkpoint is of another network ({} {}), not this configuration",
                path.display(),
                st.task,
                st.arch
            ),
        });
    }
    if (st.seed, st.batch, st.patch) != (s.seed, s.batch, s.patch) {
        return Err(NnError::BadSetting {
            flag: "--resume",
            message: format!(
                "{}: checkpoint was made with seed {}, batch {}, patch {}; resume with the same",
                path.display(),
                st.seed,
                st.batch,
                st.patch
            ),
        });
    }
    if st.step > s.steps {
        return Err(NnError::BadSetting {
            flag: "--steps",
            message: format!(
                "--resume: {} is at step {}, past --steps {}; give --steps {} or more to train on",
                path.display(),
                st.step,
                s.steps,
                st.step
            ),
        });
    }
    Ok(())
}

/// The outcome of resuming a run that had already finished: its checkpoint
/// is at `steps` and the weight file it wrote then reads back as that run's
/// (same steps). Nothing is redone or rewritten. `None` when there is work
/// left, or when the weight file is missing or not that run's (a run killed
/// between its last checkpoint and its weight file): the file is then
/// written again from the checkpoint.
fn finished(st: &CheckpointState, s: &TrainConfig, outputs: &TrainOutputs) -> Option<Outcome> {
    if st.step < s.steps {
        return None;
    }
    let meta = crate::weights::read_meta(&outputs.weights).ok()?;
    let t = meta.training.as_ref()?;
    (t.steps == st.step && (t.seed, t.batch, t.patch) == (s.seed, s.batch, s.patch)).then(|| {
        Outcome {
            start_step: st.step,
            end_step: st.step,
            losses: Vec::new(),
            final_loss: t.final_loss,
            val_psnr: t.val_psnr,
            val_input_psnr: None,
            seconds: 0.0,
            images_per_s: 0.0,
            interrupted: false,
            already_finished: true,
        }
    })
}

/// Refuse a run whose step (or validation crop) would not fit in memory.
fn check_memory(c: &TrainConfig, arch: &Architecture) -> Result<()> {
    use crate::infer::memory::{tile_bytes, training_bytes};
    let (p, b, v, n) = (c.patch, c.batch, c.val_patch(), c.val_pairs);
    // The data workers each keep two batches of crops ready besides the
    // step's own (pairs and the flow's start fields, four planes of f32).
    let queued = (c.workers.max(1) * 2 * b) as f64 * 3.0 * 16.0 * (p * p) as f64;
    let need = training_bytes(arch, p, b).max(tile_bytes(arch, v, v))
        + crate::data::validation::ValSet::bytes(v, n)
        + queued;
    pgrf_core::mem::check_fits(
        &format!(
            "training with --patch {p} --batch {b} --workers {} and {n} validation pairs of {v}",
            c.workers
        ),
        need,
    )
    .map_err(|e| {
        NnError::TooLarge(format!(
            "{e}; give a smaller --patch, --batch, --val-patch or fewer --val-pairs"
        ))
    })
}

/// The line that says what a run trains: network, data, noise, schedule,
/// device.
fn header(
    c: &TrainConfig,
    arch: &Architecture,
    train: &Source,
    mix: &PairMix,
    noise: &NoiseSource,
) -> String {
    format!(
        "training {} on {} ({}x{} crops{}, batch {}), noise {} from {}{}{}, {} steps, lr {:e} ({:?}){}{}, {} on {}",
        arch.describe(),
        train.describe(),
        c.patch,
        c.patch,
        c.window.map(|w| format!(" within windows of {w}")).unwrap_or_default(),
        c.batch,
        noise.model,
        mix.describe(),
        noise.calibration.as_ref().map(|c| format!(" + calibration {c}")).unwrap_or_default(),
        if noise.calibrated_dark_level {
            " (dark level calibrated)".to_string()
        } else if c.calibrated_share > 0.0 {
            format!(" ({:.0}% drawn with the dark level calibrated)", 100.0 * c.calibrated_share)
        } else {
            String::new()
        },
        c.steps,
        c.lr,
        c.schedule,
        if c.time_max < 1.0 { format!(", times t ~ U(0, {})", c.time_max) } else { String::new() },
        loss_words(c),
        c.device,
        crate::backend::describe(c.device, c.kernels),
    )
}

/// The loss in words for the header when it is not the plain L1 mean.
fn loss_words(c: &TrainConfig) -> String {
    use crate::config::{Distance, ItemWeight};
    let d = match c.loss {
        Distance::L1 => "L1",
        Distance::Mse => "MSE",
    };
    match (c.loss, c.item_weight) {
        (Distance::L1, ItemWeight::None) => String::new(),
        (_, ItemWeight::None) => format!(", loss {d}"),
        (_, ItemWeight::Noise) => format!(", loss {d} of each crop over its noise level"),
        (_, ItemWeight::Log) => format!(", loss the mean of ln {d} over the crops"),
    }
}

/// One run's pieces besides its configuration, resolved by [`run`], and the
/// work [`on_train_device`] runs on the configured device's backend.
struct Job<'a> {
    config: &'a TrainConfig,
    /// The network (and so the method).
    arch: Architecture,
    /// The weight file, checkpoint and log.
    outputs: TrainOutputs,
    /// Continue from the checkpoint.
    resume: bool,
    /// The noise, as the weight file records it.
    noise: NoiseSource,
    source: Arc<Source>,
    mix: Arc<PairMix>,
    val: Option<&'a ValSet>,
    progress: &'a dyn Progress,
    stop: &'a AtomicBool,
}

impl OnTrainBackend for Job<'_> {
    type Output = Outcome;
    fn run<B: PgrfAutodiff>(self, device: B::Device) -> Result<Outcome> {
        train::<B>(
            &self,
            self.source.clone(),
            self.mix.clone(),
            self.val,
            &device,
            self.progress,
            self.stop,
        )
    }
}

type Rec = BinBytesRecorder<FullPrecisionSettings>;

/// The optimiser of a training run.
type Adam<B> = OptimizerAdaptor<PgrfAdam, Net<B>, B>;

fn to_tensor<B: PgrfOps>(v: &[f32], shape: [usize; 4], device: &B::Device) -> Tensor<B, 4> {
    Tensor::from_data(TensorData::new(v.to_vec(), shape), device)
}

/// Mean PSNR of the network on the validation pairs (one at a time, so memory
/// stays that of a single patch).
pub(crate) fn validate<B: PgrfOps>(net: &Net<B>, val: &ValSet, t2: f32, device: &B::Device) -> f32 {
    let p = val.patch;
    let mut sum = 0.0;
    for pair in &val.pairs {
        let noisy = to_tensor::<B>(&pair.noisy, [1, 4, p, p], device);
        let x0 = to_tensor::<B>(&pair.x0, [1, 4, p, p], device);
        let out: Vec<f32> = net
            .restore(noisy, &[pair.level], x0, t2)
            .into_data()
            .convert::<f32>()
            .to_vec()
            .expect("f32 output");
        sum += psnr(&out, &pair.clean);
    }
    sum / val.pairs.len().max(1) as f32
}

struct Log {
    file: Option<std::fs::File>,
    json: bool,
    /// The run keeps a moving average: rows carry the raw weights' PSNR too.
    ema: bool,
}

impl Log {
    const HEADER: &'static str = "step,loss,lr,images_per_s,val_psnr,seconds";

    /// Open the log; on resume keep only the rows up to the checkpoint's step
    /// (a crash after the last checkpoint leaves rows that will be redone).
    /// With a moving average (`ema`) the rows end with the raw weights'
    /// validation PSNR (`val_psnr` is the average's).
    fn open(path: Option<&PathBuf>, resume_step: Option<u64>, ema: bool) -> Result<Log> {
        let Some(path) = path else {
            return Ok(Log {
                file: None,
                json: false,
                ema,
            });
        };
        let json = matches!(
            path.extension().and_then(|e| e.to_str()),
            Some("jsonl") | Some("json")
        );
        let mut kept = String::new();
        if let (Some(upto), Ok(text)) = (resume_step, std::fs::read_to_string(path)) {
            for line in text.lines() {
                let step = if json {
                    serde_json::from_str::<serde_json::Value>(line)
                        .ok()
                        .and_then(|v| v.get("step").and_then(|s| s.as_u64()))
                } else {
                    line.split(',').next().and_then(|s| s.parse::<u64>().ok())
                };
                if step.is_some_and(|s| s <= upto) {
                    kept.push_str(line);
                    kept.push('\n');
                }
            }
        }
        let output = |e: std::io::Error| NnError::Output {
            path: path.clone(),
            reason: e.to_string(),
        };
        let mut file = std::fs::File::create(path).map_err(output)?;
        let header = match (json, ema) {
            (true, _) => String::new(),
            (false, false) => format!("{}\n", Self::HEADER),
            (false, true) => format!("{},val_psnr_raw\n", Self::HEADER),
        };
        file.write_all(header.as_bytes())
            .and_then(|_| file.write_all(kept.as_bytes()))
            .map_err(output)?;
        Ok(Log {
            file: Some(file),
            json,
            ema,
        })
    }

    /// One row; `val` is (stored weights' PSNR, raw weights' PSNR when a
    /// moving average is kept), on validation steps.
    fn row(
        &mut self,
        step: u64,
        loss: f32,
        lr: f64,
        ips: f64,
        val: Option<(f32, Option<f32>)>,
        secs: f64,
    ) {
        let Some(f) = self.file.as_mut() else { return };
        let (v, raw) = (val.map(|v| v.0), val.and_then(|v| v.1));
        let line = if self.json {
            let mut row = serde_json::json!({"step": step, "loss": loss, "lr": lr, "images_per_s": ips,
                "val_psnr": v, "seconds": secs});
            if self.ema {
                row["val_psnr_raw"] = serde_json::json!(raw);
            }
            row.to_string()
        } else {
            let f4 = |x: Option<f32>| x.map(|x| format!("{x:.4}")).unwrap_or_default();
            let mut line = format!("{step},{loss:.6},{lr:e},{ips:.3},{},{secs:.2}", f4(v));
            if self.ema {
                line.push_str(&format!(",{}", f4(raw)));
            }
            line
        };
        // A full disk should not kill hours of training: warn once via the row loss.
        let _ = writeln!(f, "{line}");
    }
}

/// Train from scratch or resume, until `config.steps` or until `stop` is set.
fn train<B: PgrfAutodiff>(
    j: &Job,
    source: Arc<Source>,
    mix: Arc<PairMix>,
    val: Option<&ValSet>,
    device: &B::Device,
    progress: &dyn Progress,
    stop: &AtomicBool,
) -> Result<Outcome> {
    let s = j.config;
    check_step_settings(s)?;
    let (mut run, mut net) = Run::<B>::new(j, device, progress)?;
    let start = run.start;
    let mut log = Log::open(
        Some(&j.outputs.log),
        j.resume.then_some(start),
        run.ema.is_some(),
    )?;
    let sample = SampleSpec {
        patch: s.patch,
        seed: s.seed,
        augment: !s.no_augment,
        extras: j.arch.extras(s.time_max),
    };
    let mut loader = Loader::start(source, mix, sample, s.batch, start, s.workers, 2)?;
    let clock = Instant::now();
    let mut losses = Vec::new();
    let mut window = (0.0f64, 0u64);
    let mut interrupted = false;
    let mut step = start;
    progress.start(s.steps, "steps");
    progress.set_position(start);
    while step < s.steps {
        if stop.load(Ordering::Relaxed) {
            interrupted = true;
            break;
        }
        let batch = loader.next_batch()?;
        let lr = s.schedule.lr(s.lr, step, s.steps);
        let value;
        (net, value) = run.step(net, &batch, step, lr)?;
        step += 1;
        losses.push(value);
        window.0 += value as f64;
        window.1 += 1;
        let secs = clock.elapsed().as_secs_f64();
        let ips = ((step - start) as usize * s.batch) as f64 / secs.max(1e-9);
        progress.set_position(step);
        progress.message(&format!("loss {value:.4}  lr {lr:.1e}  {ips:.2} img/s"));
        let val_now = match val {
            Some(v) if s.val_every > 0 && step % s.val_every == 0 && step < s.steps => {
                Some(run.validation(&net, v, step, progress)?)
            }
            _ => None,
        };
        // The last step's row is written after the final validation.
        if (step % s.log_every.max(1) == 0 || val_now.is_some()) && step < s.steps {
            let mean = (window.0 / window.1.max(1) as f64) as f32;
            log.row(step, mean, lr, ips, val_now, run.elapsed0 + secs);
            window = (0.0, 0);
        }
        if s.checkpoint_every > 0 && step % s.checkpoint_every == 0 && step < s.steps {
            run.save_checkpoint(&net, step, run.elapsed0 + secs, Some(value))?;
        }
    }
    drop(loader);
    let end = LoopEnd {
        start,
        step,
        losses,
        window,
        interrupted,
        seconds: clock.elapsed().as_secs_f64(),
    };
    let outcome = finish(&mut run, &net, val, end, &mut log)?;
    progress.finish();
    Ok(outcome)
}

/// Where the loop of [`train`] stopped.
struct LoopEnd {
    start: u64,
    step: u64,
    losses: Vec<f32>,
    /// Sum and count of the losses since the last log row.
    window: (f64, u64),
    interrupted: bool,
    seconds: f64,
}

/// A validation's PSNR: the moving average's, and the raw weights' when a
/// moving average is kept.
type Validated = (f32, Option<f32>);

/// The run's last validation (none when it was stopped: the moving
/// average's and the raw weights' PSNR) and the noisy input's PSNR on the
/// same pairs, when there are validation pairs.
fn final_validation<B: PgrfAutodiff>(
    run: &mut Run<B>,
    net: &Net<B>,
    val: Option<&ValSet>,
    interrupted: bool,
) -> Result<(Option<Validated>, Option<f32>)> {
    let Some(v) = val else {
        return Ok((None, None));
    };
    let final_val = if interrupted {
        None
    } else {
        Some(run.validate_both(net, v)?)
    };
    let input = v
        .pairs
        .iter()
        .map(|p| psnr(&p.noisy, &p.clean))
        .sum::<f32>()
        / v.pairs.len().max(1) as f32;
    Ok((final_val, Some(input)))
}

/// The end of a run: the final validation (unless stopped), the last log
/// row, the checkpoint and the weight file with its training record.
fn finish<B: PgrfAutodiff>(
    run: &mut Run<B>,
    net: &Net<B>,
    val: Option<&ValSet>,
    end: LoopEnd,
    log: &mut Log,
) -> Result<Outcome> {
    let s = run.j.config;
    let LoopEnd {
        start,
        step,
        losses,
        window,
        interrupted,
        seconds,
    } = end;
    let images_per_s = ((step - start) as usize * s.batch) as f64 / seconds.max(1e-9);
    let (final_val, val_input_psnr) = final_validation(run, net, val, interrupted)?;
    let val_psnr = final_val.map(|(p, _)| p).or(run.last_val);
    if window.1 > 0 {
        let mean = (window.0 / window.1 as f64) as f32;
        let lr = s.schedule.lr(s.lr, step.saturating_sub(1), s.steps);
        log.row(
            step,
            mean,
            lr,
            images_per_s,
            final_val,
            run.elapsed0 + seconds,
        );
    }
    let last_loss = losses.last().copied().or(run.resumed_loss);
    // NaN (null in the record, read back as NaN) only for a run stopped
    // before its first step.
    let final_loss = last_loss.unwrap_or(f32::NAN);
    run.last_val = val_psnr;
    run.save_checkpoint(net, step, run.elapsed0 + seconds, last_loss)?;
    let summary = TrainingSummary {
        steps: step,
        batch: s.batch,
        patch: s.patch,
        seed: s.seed,
        data: s.data.clone(),
        final_loss,
        val_psnr,
        val_psnr_raw: final_val.and_then(|(_, raw)| raw),
        seconds: run.elapsed0 + seconds,
        images_per_s,
        device: s.device.to_string(),
        config: Some(s.clone()),
        started_from: run.started_from.clone(),
    };
    run.save_weights(net, summary)?;
    Ok(Outcome {
        start_step: start,
        end_step: step,
        losses,
        final_loss,
        val_psnr,
        val_input_psnr,
        seconds,
        images_per_s,
        interrupted,
        already_finished: false,
    })
}

/// Refuse settings no step can run with.
fn check_step_settings(s: &TrainConfig) -> Result<()> {
    if s.batch == 0 || s.patch == 0 {
        return Err(NnError::BadSetting {
            flag: "--batch",
            message: "batch and patch must be at least 1".into(),
        });
    }
    if !(s.lr > 0.0 && s.lr.is_finite()) {
        return Err(NnError::BadSetting {
            flag: "--lr",
            message: format!("learning rate must be > 0, got {}", s.lr),
        });
    }
    Ok(())
}

/// What the loop of [`train`] works on besides the network (which the
/// loop owns, so that each step updates it in place): its optimiser and
/// moving average, and where the run stands (its first step, the time and
/// the last validation of the runs before it).
struct Run<'j, 'a, B: PgrfAutodiff> {
    j: &'j Job<'a>,
    device: &'j B::Device,
    optim: Adam<B>,
    ema: Option<Ema>,
    recorder: Rec,
    arch_json: serde_json::Value,
    started_from: Option<StartedFrom>,
    start: u64,
    elapsed0: f64,
    last_val: Option<f32>,
    /// The loss of the checkpoint's last step: a resumed run that runs no
    /// step (its weight file lost) records it.
    resumed_loss: Option<f32>,
}

impl<'j, 'a, B: PgrfAutodiff> Run<'j, 'a, B> {
    /// The network as the run starts: fresh (seeded), from `init`'s weights,
    /// or from the checkpoint when resuming; Adam (burn's defaults, epsilon
    /// 1e-8, one pass per parameter tensor on the CPU), clipped gradients
    /// if asked, the moving average.
    fn new(
        j: &'j Job<'a>,
        device: &'j B::Device,
        progress: &dyn Progress,
    ) -> Result<(Self, Net<B>)> {
        let s = j.config;
        let arch_json =
            serde_json::to_value(&j.arch).map_err(|e| NnError::Invalid(e.to_string()))?;
        let (mut net, started_from) = initial_net::<B>(j, device, progress)?;
        let mut optim = Adam::<B>::from(PgrfAdam::new(0.9, 0.999, 1e-8));
        if let Some(c) = s.clip_grad {
            optim = optim.with_grad_clipping(GradientClippingConfig::Norm(c).init());
        }
        let recorder = Rec::default();
        let mut at = Resumed::default();
        if j.resume {
            (net, optim, at) = resume(j, net, optim, &recorder, device, progress)?;
        }
        let mut run = Run {
            j,
            device,
            optim,
            ema: None,
            recorder,
            arch_json,
            started_from,
            start: at.step,
            elapsed0: at.elapsed_s,
            last_val: at.last_val,
            resumed_loss: at.last_loss,
        };
        let saved_ema = at.ema;
        // Statistics windows as the frames will be restored with (none: each
        // crop whole); not part of the weights, so set after any loading.
        let net = net
            .with_window(s.window.unwrap_or(0))
            .map_err(|e| NnError::BadSetting {
                flag: "--window",
                message: format!("--window: {e}"),
            })?;
        run.ema = match (s.ema, saved_ema) {
            (None, _) => None,
            (Some(d), Some(bytes)) => Some(Ema::from_bytes(d, &bytes, &j.outputs.checkpoint)?),
            (Some(d), None) => {
                if j.resume {
                    progress.note(
                        "the checkpoint holds no moving average: it starts from the resumed weights",
                    );
                }
                Some(Ema::start(d, net.parameters()))
            }
        };
        Ok((run, net))
    }

    /// One optimiser step on `batch` at learning rate `lr`; its loss.
    fn step(&mut self, net: Net<B>, batch: &Batch, step: u64, lr: f64) -> Result<(Net<B>, f32)> {
        let (s, device) = (self.j.config, self.device);
        let shape = [s.batch, 4, s.patch, s.patch];
        let loss = net.loss(
            to_tensor::<B>(&batch.noisy, shape, device),
            to_tensor::<B>(&batch.clean, shape, device),
            &batch.levels,
            s.loss_rule(),
            || to_tensor::<B>(&batch.x0, shape, device),
            || Tensor::<B, 1>::from_data(TensorData::new(batch.t.clone(), [s.batch]), device),
        );
        let value: f32 = loss.clone().into_scalar().elem();
        if !value.is_finite() {
            return Err(NnError::Diverged { step, loss: value });
        }
        let grads = GradientsParams::from_grads(loss.backward(), &net);
        let net = self.optim.step(lr, net, grads);
        if let Some(e) = self.ema.as_mut() {
            e.update(step, &net.parameters());
        }
        Ok((net, value))
    }

    /// Validation during the run, said to `progress`: (stored, raw).
    fn validation(
        &mut self,
        net: &Net<B>,
        v: &ValSet,
        step: u64,
        progress: &dyn Progress,
    ) -> Result<(f32, Option<f32>)> {
        let (p, raw) = self.validate_both(net, v)?;
        progress.note(&format!(
            "step {step}: validation PSNR {p:.2} dB{}",
            raw.map(|r| format!(" (moving average; raw weights {r:.2} dB)"))
                .unwrap_or_default()
        ));
        self.last_val = Some(p);
        Ok((p, raw))
    }

    /// Validation of the weights a run stores (the moving average when it
    /// keeps one) and, with an average, of the raw weights: (stored, raw).
    fn validate_both(&self, net: &Net<B>, v: &ValSet) -> Result<(f32, Option<f32>)> {
        let s = self.j.config;
        let raw = validate(&net.valid(), v, s.val_t2, self.device);
        Ok(match &self.ema {
            None => (raw, None),
            Some(e) => {
                let avg = e
                    .network::<B::InnerBackend>(&self.j.arch, self.device)?
                    .with_window(s.window.unwrap_or(0))
                    .map_err(|e| NnError::Invalid(e.to_string()))?;
                (validate(&avg, v, s.val_t2, self.device), Some(raw))
            }
        })
    }

    /// Write the checkpoint at `step` (network, Adam state, moving average,
    /// counters; the last validation is the run's own).
    fn save_checkpoint(
        &self,
        net: &Net<B>,
        step: u64,
        elapsed: f64,
        last_loss: Option<f32>,
    ) -> Result<()> {
        let (j, s) = (self.j, self.j.config);
        let bad = |e: burn::record::RecorderError| NnError::Invalid(e.to_string());
        let model = self
            .recorder
            .record(net.clone().into_record(), ())
            .map_err(bad)?;
        let opt = self
            .recorder
            .record(self.optim.to_record(), ())
            .map_err(bad)?;
        let state = CheckpointState {
            task: j.arch.method(),
            arch: self.arch_json.clone(),
            step,
            steps: s.steps,
            seed: s.seed,
            batch: s.batch,
            patch: s.patch,
            elapsed_s: elapsed,
            last_loss,
            last_val_psnr: self.last_val,
        };
        let ema = self
            .ema
            .as_ref()
            .map(Ema::to_bytes)
            .transpose()?
            .unwrap_or_default();
        checkpoint::save(&j.outputs.checkpoint, &state, &model, &opt, &ema)
    }

    /// Write the weight file: the moving average when the run keeps one.
    fn save_weights(&self, net: &Net<B>, training: TrainingSummary) -> Result<()> {
        let j = self.j;
        let mut meta = WeightMeta::new(j.arch.clone(), j.noise.clone());
        meta.training = Some(training);
        match &self.ema {
            Some(e) => e
                .network::<B::InnerBackend>(&j.arch, self.device)?
                .save(&j.outputs.weights, &meta),
            None => net.valid().save(&j.outputs.weights, &meta),
        }
    }
}

/// Where a resumed run's checkpoint left it (all zero for a new run).
#[derive(Default)]
struct Resumed {
    step: u64,
    elapsed_s: f64,
    last_val: Option<f32>,
    last_loss: Option<f32>,
    /// The moving average's bytes, if the checkpoint holds one.
    ema: Option<Vec<u8>>,
}

/// Load the checkpoint's network and optimiser into `net` and `optim`, and
/// where it stands.
fn resume<B: PgrfAutodiff>(
    j: &Job,
    net: Net<B>,
    optim: Adam<B>,
    recorder: &Rec,
    device: &B::Device,
    progress: &dyn Progress,
) -> Result<(Net<B>, Adam<B>, Resumed)> {
    let ck = checkpoint::load(&j.outputs.checkpoint)?;
    let st = &ck.state;
    check_resumable(st, &j.arch, j.config, &j.outputs.checkpoint)?;
    let bad = |e: burn::record::RecorderError| NnError::BadFile {
        path: j.outputs.checkpoint.clone(),
        reason: e.to_string(),
    };
    let net = net.load_record(recorder.load(ck.model, device).map_err(bad)?);
    let optim = optim.load_record(recorder.load(ck.optim, device).map_err(bad)?);
    progress.note(&format!(
        "resumed from {} at step {}",
        j.outputs.checkpoint.display(),
        st.step
    ));
    let at = Resumed {
        step: st.step,
        elapsed_s: st.elapsed_s,
        last_val: st.last_val_psnr,
        last_loss: st.last_loss,
        ema: ck.ema,
    };
    Ok((net, optim, at))
}

/// The network a run starts from before any checkpoint: seeded fresh
/// weights, or `init`'s (a resumed run reads only `init`'s record), with
/// the run's prior loaded into a flow that reads one.
fn initial_net<B: PgrfAutodiff>(
    j: &Job,
    device: &B::Device,
    progress: &dyn Progress,
) -> Result<(Net<B>, Option<StartedFrom>)> {
    let net: Net<B> = j.arch.init_seeded(device, j.config.seed)?;
    match &j.config.init {
        None if j.resume => Ok((net, None)),
        None => Ok((with_prior(net, j.config, device)?, None)),
        Some(path) if j.resume => Ok((
            net,
            Some(StartedFrom::of(
                path,
                &crate::weights::require_arch(path, &j.arch)?,
            )),
        )),
        Some(path) => {
            let (trained, meta, adapted) =
                crate::model::load_init::<B>(path, &j.arch, net, device)?;
            if let Some(note) = adapted_note(adapted, path, j.config.seed) {
                progress.note(&note);
            }
            let trained = with_prior(trained, j.config, device)?;
            Ok((trained, Some(StartedFrom::of(path, &meta))))
        }
    }
}

/// What the run says about how `init`'s weights (`path`) were fitted, if
/// they were.
fn adapted_note(adapted: StartAdapted, path: &std::path::Path, seed: u64) -> Option<String> {
    match adapted {
        StartAdapted::AsIs => None,
        StartAdapted::Conditioned => Some(format!(
            "starting from {}'s unconditioned weights: the noise planes' input weights start at zero",
            path.display()
        )),
        StartAdapted::Widened { from, to } => Some(format!(
            "starting from {}'s width-{from} weights in the old channels of width {to}: the new channels start from seed {seed} and are read through weights that start at zero",
            path.display(),
        )),
        StartAdapted::PriorAdded => Some(format!(
            "starting from {}'s weights with the prior's restoration read through weights that start at zero and a last layer at zero: the flow starts out sampling the prior's restoration",
            path.display()
        )),
    }
}

/// `net` with the weights of the run's `prior` (an SPC weight file) in
/// its frozen denoiser; unchanged without one.
fn with_prior<B: PgrfAutodiff>(net: Net<B>, c: &TrainConfig, device: &B::Device) -> Result<Net<B>> {
    let Some(path) = &c.prior else {
        return Ok(net);
    };
    match net {
        Net::Pgrf(flow) => {
            let (_, tensors) = crate::weights::read(path)?;
            flow.with_prior_weights(&tensors, device)
                .map(Net::Pgrf)
                .map_err(|e| NnError::SizeMismatch(format!("--prior {}: {e}", path.display())))
        }
        spc => Ok(spc),
    }
}
