//! Training batches, made ahead of the optimiser by worker threads.
//!
//! Every sample is a pure function of (run seed, sample index): which image,
//! where to crop, which flips, the noise, and for the flow model X0 and t.
//! Workers therefore need no shared random state, any number of them gives
//! the same batches in the same order, and resuming at step s regenerates
//! exactly the batches an uninterrupted run would have seen.
//!
//! Augmentation (flips, transpose) is applied to the clean crop *before* the
//! noise is synthesised: row noise and per-pixel maps belong to the sensor's
//! orientation, and a transposed pair would teach the network column noise
//! that no camera makes.

use crate::condition::NoiseLevel;
use crate::data::augment::Augment;
use crate::data::source::Source;
use crate::error::{NnError, Result};
use pgrf_core::seed::mix64;
use pgrf_noise::mix::PairMix;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use std::sync::mpsc::{sync_channel, Receiver};
use std::sync::Arc;
use std::thread::JoinHandle;

pub(crate) use crate::arch::Extras;

/// One batch, NCHW f32 (`(n, 4, P, P)` flattened), ready to become tensors.
#[derive(Clone, Debug)]
pub(crate) struct Batch {
    /// Network input: noisy capture amplified by its ratio, clipped at 1
    /// (values below black kept).
    pub(crate) noisy: Vec<f32>,
    /// Target: the clean crops X1 in [0, 1].
    pub(crate) clean: Vec<f32>,
    /// Flow only: X0 (same shape) and t (one per item).
    pub(crate) x0: Vec<f32>,
    /// Flow only: t ~ U(0, t_max), one per item.
    pub(crate) t: Vec<f32>,
    /// Exposure ratio of each item.
    pub(crate) ratios: Vec<f32>,
    /// Noise level of each item's input (what a conditioned network is told).
    pub(crate) levels: Vec<NoiseLevel>,
}

/// How samples are drawn.
#[derive(Clone, Debug)]
pub(crate) struct SampleSpec {
    /// Side of the packed crops.
    pub(crate) patch: usize,
    /// Seed of the run: sample i is a function of (seed, i).
    pub(crate) seed: u64,
    /// Draw flips and transposes.
    pub(crate) augment: bool,
    /// What else each item carries.
    pub(crate) extras: Extras,
}

const SAMPLE_DOMAIN: u64 = 0x7261_696e; // "rain"
const SCENE_DOMAIN: u64 = 0x7363_656e; // "scen"

fn rng_for(seed: u64, domain: u64, index: u64) -> Xoshiro256PlusPlus {
    Xoshiro256PlusPlus::seed_from_u64(mix64(mix64(seed ^ domain) ^ index))
}

/// One training item, `(4, P, P)` arrays flattened.
#[derive(Clone, Debug)]
pub(crate) struct Sample {
    /// Amplified noisy crop, clipped at 1 (values below black kept).
    pub(crate) noisy: Vec<f32>,
    /// Clean crop in [0, 1].
    pub(crate) clean: Vec<f32>,
    /// Flow only (empty otherwise).
    pub(crate) x0: Vec<f32>,
    /// Flow only: t ~ U(0, 1) (0 otherwise).
    pub(crate) t: f32,
    /// The exposure ratio the pair was synthesised at.
    pub(crate) ratio: f32,
    /// The noise level of `noisy`, from the parameters the pair was drawn
    /// with.
    pub(crate) level: NoiseLevel,
}

/// Sample `index` of the run: one (noisy, clean[, x0, t]) item.
pub(crate) fn make_sample(
    source: &Source,
    mix: &PairMix,
    s: &SampleSpec,
    index: u64,
) -> Result<Sample> {
    let mut rng = rng_for(s.seed, SAMPLE_DOMAIN, index);
    let pick = rng.random::<u64>();
    let (fy, fx) = (rng.random::<f64>(), rng.random::<f64>());
    let aug = if s.augment {
        Augment::draw(&mut rng)
    } else {
        Augment::IDENTITY
    };
    let scene_seed = mix64(mix64(s.seed ^ SCENE_DOMAIN) ^ index);
    // The camera of a mix comes from the scene seed, so a single camera's
    // draws are exactly what they were before mixes existed.
    let spec = mix.pick(scene_seed);
    let crop = source.crop(s.patch, scene_seed, pick, fy, fx)?;
    let clean = aug.apply(crop.clean.view());
    let mut local = spec.clone();
    if let Some(maps) = &spec.maps {
        // The maps of the sensor window the crop stands for: the file's own
        // position when the calibration covers the file, otherwise a random
        // window of the calibrated sensor.
        let (mh, mw) = maps.pixel_shape().unwrap_or((s.patch, s.patch));
        if mh < s.patch || mw < s.patch {
            return Err(NnError::SizeMismatch(format!(
                "calibration maps pack to {mh}x{mw}, smaller than the {0}x{0} patch",
                s.patch
            )));
        }
        let (y, x) = if (mh, mw) == crop.image {
            crop.origin
        } else {
            (
                (rng.random::<f64>() * (mh - s.patch + 1) as f64) as usize,
                (rng.random::<f64>() * (mw - s.patch + 1) as f64) as usize,
            )
        };
        local.maps = Some(maps.crop(y.min(mh - s.patch), x.min(mw - s.patch), s.patch, s.patch)?);
    }
    let synth_seed = rng.random::<u64>();
    let pair = local.synthesize(clean.view(), crop.plane_rows, synth_seed)?;
    // Clipped at white only: a network that reads values below black
    // clamped gets them clamped by `Net` itself (`Net::as_read`).
    let noisy: Vec<f32> = pair.noisy.iter().map(|v| v.min(1.0)).collect();
    let clean: Vec<f32> = pair.clean.iter().copied().collect();
    let (x0, t) = match s.extras {
        Extras::None => (Vec::new(), 0.0),
        Extras::Flow { t_max } => {
            crate::flow::draw::training_start_and_time(&mut rng, noisy.len(), t_max)
        }
    };
    let level = NoiseLevel::from_dn(
        pair.params.k,
        pair.params.sigma_gauss,
        pair.params.sigma_row,
        local.dn_range(),
        pair.ratio as f64,
    );
    Ok(Sample {
        noisy,
        clean,
        x0,
        t,
        ratio: pair.ratio,
        level,
    })
}

/// Batch `b` (items b*n .. b*n+n-1).
pub(crate) fn make_batch(
    source: &Source,
    mix: &PairMix,
    s: &SampleSpec,
    n: usize,
    b: u64,
) -> Result<Batch> {
    let mut batch = Batch {
        noisy: Vec::with_capacity(n * 4 * s.patch * s.patch),
        clean: Vec::with_capacity(n * 4 * s.patch * s.patch),
        x0: Vec::new(),
        t: Vec::new(),
        ratios: Vec::new(),
        levels: Vec::new(),
    };
    for i in 0..n as u64 {
        let item = make_sample(source, mix, s, b * n as u64 + i)?;
        batch.noisy.extend(item.noisy);
        batch.clean.extend(item.clean);
        batch.x0.extend(item.x0);
        if matches!(s.extras, Extras::Flow { .. }) {
            batch.t.push(item.t);
        }
        batch.ratios.push(item.ratio);
        batch.levels.push(item.level);
    }
    Ok(batch)
}

/// Worker threads producing batches `start, start+1, ...` in order.
pub(crate) struct Loader {
    receivers: Vec<Receiver<Result<Batch>>>,
    next: u64,
    start: u64,
    handles: Vec<JoinHandle<()>>,
}

impl Loader {
    /// `workers` threads, each keeping up to `ahead` batches ready.
    pub(crate) fn start(
        source: Arc<Source>,
        mix: Arc<PairMix>,
        sample: SampleSpec,
        batch: usize,
        start: u64,
        workers: usize,
        ahead: usize,
    ) -> Result<Loader> {
        let workers = workers.max(1);
        let mut receivers = Vec::new();
        let mut handles = Vec::new();
        for w in 0..workers as u64 {
            let (tx, rx) = sync_channel(ahead.max(1));
            let (source, mix, sample) = (source.clone(), mix.clone(), sample.clone());
            let h = std::thread::Builder::new()
                .name(format!("pgrf-data-{w}"))
                .spawn(move || {
                    let mut b = start + w;
                    loop {
                        let r = make_batch(&source, &mix, &sample, batch, b);
                        let failed = r.is_err();
                        // The trainer hung up: stop quietly.
                        if tx.send(r).is_err() || failed {
                            return;
                        }
                        b += workers as u64;
                    }
                })
                .map_err(|e| {
                    NnError::TooLarge(format!(
                        "starting data thread {} of {workers}: {e}; give fewer --workers",
                        w + 1
                    ))
                })?;
            receivers.push(rx);
            handles.push(h);
        }
        Ok(Loader {
            receivers,
            next: start,
            start,
            handles,
        })
    }

    /// The next batch in order.
    pub(crate) fn next_batch(&mut self) -> Result<Batch> {
        let w = ((self.next - self.start) % self.receivers.len() as u64) as usize;
        self.next += 1;
        self.receivers[w]
            .recv()
            .map_err(|_| NnError::Invalid("a data worker stopped unexpectedly".into()))?
    }
}

/// Crops per second the loader alone delivers: `batches` batches of
/// `batch` crops of `source` from `workers` threads, as `pgrf train` runs
/// them beside the optimiser (no augmentation skipped, the denoiser's
/// items), timed after each worker's first batch (caches warm).
pub fn loader_rate(
    source: Arc<Source>,
    mix: Arc<PairMix>,
    patch: usize,
    batch: usize,
    workers: usize,
    batches: u64,
) -> Result<f64> {
    let sample = SampleSpec {
        patch,
        seed: 0,
        augment: true,
        extras: Extras::None,
    };
    let mut loader = Loader::start(source, mix, sample, batch, 0, workers, 2)?;
    for _ in 0..workers.max(1) {
        loader.next_batch()?;
    }
    let t = std::time::Instant::now();
    for _ in 0..batches {
        loader.next_batch()?;
    }
    Ok((batches as usize * batch) as f64 / t.elapsed().as_secs_f64())
}

impl Drop for Loader {
    fn drop(&mut self) {
        // Hang up first so blocked workers see a closed channel, then join.
        self.receivers.clear();
        for h in self.handles.drain(..) {
            let _ = h.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pgrf_noise::pair::PairSpec;
    use pgrf_noise::{CameraProfile, ModelKind};

    fn spec() -> PairSpec {
        let mut p = PairSpec::new(
            CameraProfile::built_in("sony-a7s2").unwrap(),
            ModelKind::Pgrf,
        );
        p.iso = Some(1600);
        p
    }

    #[test]
    fn batches_do_not_depend_on_the_worker_count_or_the_start() {
        let sample = SampleSpec {
            patch: 32,
            seed: 3,
            augment: true,
            extras: Extras::Flow { t_max: 1.0 },
        };
        let src = Arc::new(Source::Procedural);
        let sp = Arc::new(PairMix::from(spec()));
        let mut one = Loader::start(src.clone(), sp.clone(), sample.clone(), 2, 0, 1, 1).unwrap();
        let mut three = Loader::start(src.clone(), sp.clone(), sample.clone(), 2, 0, 3, 2).unwrap();
        let mut late = Loader::start(src, sp, sample, 2, 2, 2, 1).unwrap();
        let a: Vec<Batch> = (0..4).map(|_| one.next_batch().unwrap()).collect();
        let b: Vec<Batch> = (0..4).map(|_| three.next_batch().unwrap()).collect();
        let c = late.next_batch().unwrap();
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.noisy, y.noisy);
            assert_eq!(x.x0, y.x0);
            assert_eq!(x.t, y.t);
        }
        assert_eq!(a[2].clean, c.clean);
        assert_ne!(a[0].clean, a[1].clean);
        assert_eq!(a[0].noisy.len(), 2 * 4 * 32 * 32);
        assert_eq!(a[0].t.len(), 2);
        // Clipped at white only (values below black kept).
        assert!(a[0].noisy.iter().all(|v| v.is_finite() && *v <= 1.0));
        // X0 ~ N(0, 1): 8192 draws, mean within 5 SE, variance within 10 %.
        let n = a[0].x0.len() as f64;
        let m = a[0].x0.iter().map(|&v| v as f64).sum::<f64>() / n;
        let v = a[0].x0.iter().map(|&v| (v as f64 - m).powi(2)).sum::<f64>() / n;
        assert!(m.abs() < 5.0 / n.sqrt(), "{m}");
        assert!((v - 1.0).abs() < 0.1, "{v}");
    }

    #[test]
    fn the_noisy_input_tracks_the_clean_target() {
        // Under Poisson-Gaussian noise (no dark current or black-level error,
        // which the richer models add on purpose) the amplified noisy crop is
        // an unbiased copy of the clean one away from the clipping points:
        // the means over mid-grey content agree within a few percent.
        let mut spec = spec();
        spec.kind = ModelKind::PoissonGaussian;
        let sample = SampleSpec {
            patch: 64,
            seed: 9,
            augment: false,
            extras: Extras::None,
        };
        let b = make_batch(&Source::Procedural, &spec.into(), &sample, 2, 0).unwrap();
        let (mut sn, mut sc, mut k) = (0.0f64, 0.0f64, 0usize);
        for (n, c) in b.noisy.iter().zip(&b.clean) {
            if (0.2..0.8).contains(c) {
                sn += *n as f64;
                sc += *c as f64;
                k += 1;
            }
        }
        assert!(k > 100, "{k}");
        assert!((sn / sc - 1.0).abs() < 0.05, "{}", sn / sc);
        assert!(b.ratios.iter().all(|r| (100.0..=300.0).contains(r)));
    }

    /// Photos mixed with procedural scenes: the same bytes from one worker
    /// or three, and both sources drawn (about in proportion to their
    /// weights 3:1).
    #[test]
    fn photo_mixtures_are_repeatable_across_worker_counts() {
        use crate::data::photos::{PhotoFolder, PhotoOptions};
        let dir = std::env::temp_dir().join(format!("pgrf-loader-photos-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let mut files = Vec::new();
        for k in 0..3u32 {
            let img = image::RgbImage::from_fn(160, 128, |x, y| {
                let v = |c: u32| ((x * (2 + c + k) + y * (3 + 2 * c) + 50 * k) % 256) as u8;
                image::Rgb([v(0), v(1), v(2)])
            });
            let p = dir.join(format!("p{k}.png"));
            img.save(&p).unwrap();
            files.push(p);
        }
        let open = || {
            let opts = PhotoOptions {
                camera: pgrf_scenes::unprocess::CameraSpace::sony_a7s2(),
                downscale: 2,
                inverse_tone: false,
                wb_spread: crate::data::photos::WB_SPREAD,
                jitter: true,
            };
            PhotoFolder::open(files.clone(), opts, 32, 16).unwrap().0
        };
        let mix = |f| {
            Arc::new(Source::Mixture(vec![
                (3.0, Source::Photos(f)),
                (1.0, Source::Procedural),
            ]))
        };
        let sample = SampleSpec {
            patch: 32,
            seed: 4,
            augment: true,
            extras: Extras::None,
        };
        let sp = Arc::new(PairMix::from(spec()));
        let mut one = Loader::start(mix(open()), sp.clone(), sample.clone(), 4, 0, 1, 1).unwrap();
        let mut three = Loader::start(mix(open()), sp, sample, 4, 0, 3, 2).unwrap();
        let mut photo_like = 0;
        for _ in 0..10 {
            let (a, b) = (one.next_batch().unwrap(), three.next_batch().unwrap());
            assert_eq!(a.noisy, b.noisy);
            assert_eq!(a.clean, b.clean);
            // Unprocessed photos are quantised to the camera's 15871 DN
            // steps; dead-leaves crops are not.
            for item in a.clean.chunks(4 * 32 * 32) {
                let on_grid = item
                    .iter()
                    .all(|v| ((v * 15871.0).round() - v * 15871.0).abs() < 1e-2);
                photo_like += on_grid as usize;
            }
        }
        // 40 items, P(photo) = 3/4: 30 expected, binomial SD 2.7.
        assert!((22..=38).contains(&photo_like), "{photo_like}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
