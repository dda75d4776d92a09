//! `pgrf demo`'s recipe: the whole product on one clean frame. A real
//! photograph or pgrf's procedural scene ([`Scene`]) is captured x100 and
//! x200 too dark at ISO 1600 through the Sony A7S2 noise model, the camera
//! counted as calibrated (its black-level error at the ISO subtracted, as
//! `pgrf enhance --calib` does); both captures are restored by an SPC and a
//! PGRF model and scored under the ELD protocol, and the clean frame, the
//! captures and the restorations are written as DNGs beside one picture
//! with everything side by side.
//!
//! - `scene`: the clean frame.
//! - `picture`: the side-by-side picture.

mod picture;
mod scene;

use crate::enhance::describe_method;
pub use crate::enhance::BoxError;
use ndarray::Array3;
use pgrf_core::{NoProgress, Progress};
use pgrf_eval::dataset::table::Row;
use pgrf_eval::{evaluate, MetricError, Protocol, Scores};
use pgrf_nn::condition::NoiseLevel;
use pgrf_nn::infer::prepare::network_input;
use pgrf_nn::infer::{restore_frame, Restore, Tiling};
use pgrf_nn::{DeviceKind, NnError};
use pgrf_noise::capture::DarkCapture;
use pgrf_noise::{CameraProfile, ModelKind, NoiseError};
use pgrf_raw::{pack_normalized, unpack_normalized, write_dng, DngOptions, RawError, RawFrame};
pub use scene::{Clean, PhotoSource, Scene};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The two captures, as in ELD's test set.
pub const RATIOS: [u32; 2] = [100, 200];
/// Their ISO.
pub const ISO: u32 = 1600;
/// Exposure of the clean frame; the dark ones get this / ratio.
pub const CLEAN_EXPOSURE_S: f64 = 1.0;
/// The columns of the demo's table, in order.
pub const METHODS: [&str; 3] = ["noisy input", "SPC", "PGRF"];

/// Why the demo stopped.
#[derive(Debug, thiserror::Error)]
pub enum DemoError {
    /// The models could not be loaded (the loader's error, unchanged).
    #[error(transparent)]
    Models(BoxError),
    /// The photograph given could not be decoded.
    #[error("--photo {}", path.display())]
    Photo {
        /// The file.
        path: PathBuf,
        /// Why not.
        #[source]
        source: RawError,
    },
    /// The window asked for is larger than the photograph.
    #[error("--size {}x{} is larger than {name} ({}x{})", size.0, size.1, frame.0, frame.1)]
    Size {
        /// The window's width and height.
        size: (usize, usize),
        /// The photograph's name.
        name: String,
        /// The photograph's width and height.
        frame: (usize, usize),
    },
    /// The built-in camera profile the captures are simulated with is missing.
    #[error("no {0} profile")]
    NoProfile(&'static str),
    /// The output folder could not be created.
    #[error("creating output folder {}", path.display())]
    Folder {
        /// The folder.
        path: PathBuf,
        /// Why not.
        #[source]
        source: std::io::Error,
    },
    /// A DNG could not be written.
    #[error("{}", path.display())]
    Dng {
        /// The file.
        path: PathBuf,
        /// Why not.
        #[source]
        source: RawError,
    },
    /// The picture could not be written.
    #[error("{}: {reason}", path.display())]
    Picture {
        /// The file.
        path: PathBuf,
        /// Why not.
        reason: pgrf_report::ReportError,
    },
    /// Decoding, packing or previewing a frame.
    #[error(transparent)]
    Raw(#[from] RawError),
    /// Rendering the procedural scene.
    #[error(transparent)]
    Scene(#[from] pgrf_scenes::SceneError),
    /// Simulating a capture.
    #[error(transparent)]
    Noise(#[from] NoiseError),
    /// Preparing a network input or restoring a capture.
    #[error(transparent)]
    Network(#[from] NnError),
    /// Scoring an image.
    #[error(transparent)]
    Metric(#[from] MetricError),
}

/// The two models the demo compares.
pub struct Models {
    /// The SPC denoiser.
    pub spc: Box<dyn Restore>,
    /// The PGRF flow model.
    pub pgrf: Box<dyn Restore>,
}

/// What the demo starts from and where it writes.
pub struct DemoConfig<'a> {
    /// Output folder (created if missing; its parent must exist).
    pub output: PathBuf,
    /// The clean frame.
    pub scene: Scene<'a>,
    /// Seed of the scene and of the noise (and of the flow's start noise).
    pub seed: u64,
    /// Tile side in packed pixels (None: as `pgrf enhance` chooses).
    pub tile: Option<usize>,
    /// Whose CPU operations the networks run.
    pub kernels: pgrf_nn::ops::Kernels,
}

/// One capture's scores, in table order: noisy input, SPC, PGRF.
#[derive(Clone, Debug)]
pub struct CaptureScores {
    /// The exposure ratio.
    pub ratio: u32,
    /// Noisy input, SPC, PGRF.
    pub scores: [Scores; 3],
}

/// What the demo did.
pub struct Demo {
    /// The clean frame, in words.
    pub what: String,
    /// The SPC model and the PGRF model, each in one phrase.
    pub models: [String; 2],
    /// The measurement.
    pub protocol: Protocol,
    /// Per ratio, the scores.
    pub captures: Vec<CaptureScores>,
    /// The picture written.
    pub picture: PathBuf,
    /// Seconds from start to end.
    pub seconds: f64,
}

impl Demo {
    /// The scores by ratio (`{"x100": {"noisy": {"psnr", "ssim"}, "spc":
    /// .., "pgrf": ..}, .., "seconds": s}`): what `pgrf demo --json` prints.
    pub fn json(&self) -> serde_json::Value {
        let s = |x: &Scores| serde_json::json!({"psnr": x.psnr, "ssim": x.ssim});
        let mut obj = serde_json::Map::new();
        for c in &self.captures {
            obj.insert(
                format!("x{}", c.ratio),
                serde_json::json!({"noisy": s(&c.scores[0]), "spc": s(&c.scores[1]), "pgrf": s(&c.scores[2])}),
            );
        }
        obj.insert("seconds".into(), serde_json::json!(self.seconds));
        serde_json::Value::Object(obj)
    }

    /// The scores as table rows (id "demo", one row group per ratio).
    pub fn rows(&self) -> Vec<Row> {
        let mut rows = Vec::new();
        for c in &self.captures {
            for (m, s) in METHODS.iter().zip(&c.scores) {
                rows.push(Row {
                    protocol: s.protocol.clone(),
                    id: "demo".into(),
                    group: c.ratio,
                    ratio: c.ratio as f32,
                    noisy: format!("noisy_x{}.dng", c.ratio),
                    reference: "clean.dng".into(),
                    method: (*m).into(),
                    psnr: s.psnr,
                    ssim: s.ssim,
                    gain: s.gain,
                    iso: None,
                    seed: None,
                    cast: None,
                    black: None,
                    noise: None,
                });
            }
        }
        rows
    }
}

/// One capture's frames and scores.
pub(crate) struct Capture {
    pub(crate) ratio: u32,
    /// The simulated capture, as the camera wrote it.
    pub(crate) dark: RawFrame,
    /// What the denoisers and the noisy score saw: the capture minus its
    /// calibrated dark level (before the ratio), for the noisy panel.
    pub(crate) calibrated: RawFrame,
    pub(crate) scores: [Scores; 3],
    pub(crate) restored: [RawFrame; 2],
}

/// What every capture shares: the clean frame, its packed reference, the
/// models, the camera and the tiling.
struct Bench<'a> {
    clean: &'a RawFrame,
    reference: Array3<f32>,
    models: &'a Models,
    profile: CameraProfile,
    seed: u64,
    tiling: Tiling,
}

impl Bench<'_> {
    /// Capture the clean frame at capture number `k`'s ratio and restore it
    /// with both models; `progress` hears a message per stage and one step
    /// for the capture and each model.
    fn capture(&self, k: usize, progress: &dyn Progress) -> Result<Capture, DemoError> {
        let (ratio, reference) = (RATIOS[k], &self.reference);
        let protocol = Protocol::eld(false);
        progress.message(&format!("x{ratio}: simulating the capture"));
        let dark_model = DarkCapture {
            profile: self.profile.clone(),
            model: ModelKind::Pgrf,
            iso: ISO,
            exposure_s: CLEAN_EXPOSURE_S / ratio as f64,
            ratio: ratio as f32,
            seed: self.seed.wrapping_mul(1_000_003).wrapping_add(k as u64 + 1),
        };
        let dark = dark_model.take(self.clean)?;
        // The simulated camera is calibrated: its black-level error at the
        // ISO is known (bias frames), subtracted as `enhance --calib` does.
        let dark_dn = dark_model.dark_level_dn(self.clean)?;
        let input = network_input(&dark, ratio as f32, Some(&dark_dn))?;
        let noisy = evaluate(input.view(), reference.view(), &protocol)?;
        progress.advance(1);
        let run = |r: &dyn Restore, name: &str| -> Result<(Scores, RawFrame), DemoError> {
            progress.message(&format!("x{ratio}: {name}"));
            // A noise-aware model is told the capture's noise as a
            // calibration of the simulated camera states it (the profile's
            // parameters at the ISO, on its DN range), as `enhance --calib`
            // tells it a real calibration's: the demo's camera counts as
            // calibrated, and a small window has too few flat blocks for
            // the blind estimate a RAW of an unknown camera would get.
            let level = match r.meta().arch.conditioning().needs_level() {
                true => {
                    let p = self.profile.params_at_iso(ISO)?;
                    Some(NoiseLevel::from_dn(
                        p.k,
                        p.sigma_gauss,
                        p.sigma_row,
                        self.profile.dn_range(),
                        ratio as f64,
                    ))
                }
                false => None,
            };
            let out = restore_frame(
                r,
                &dark,
                ratio as f32,
                Some(&dark_dn),
                level,
                &self.tiling,
                &NoProgress,
            )?;
            let s = evaluate(out.packed.output.view(), reference.view(), &protocol)?;
            progress.advance(1);
            Ok((s, out.frame))
        };
        let (spc_s, spc_f) = run(self.models.spc.as_ref(), "SPC")?;
        let (pgrf_s, pgrf_f) = run(self.models.pgrf.as_ref(), "PGRF")?;
        let calibrated = unpack_normalized(input.mapv(|v| v / ratio as f32).view(), &dark)?;
        Ok(Capture {
            ratio,
            dark,
            calibrated,
            scores: [noisy, spc_s, pgrf_s],
            restored: [spc_f, pgrf_f],
        })
    }
}

/// Write the clean frame, each capture and its restorations as DNGs in `dir`.
fn write_dngs(dir: &Path, clean: &RawFrame, captures: &[Capture]) -> Result<(), DemoError> {
    let dng = |f: &RawFrame, name: &str| -> Result<(), DemoError> {
        let path = dir.join(name);
        write_dng(f, &path, &DngOptions::default())
            .map_err(|source| DemoError::Dng { path, source })
    };
    dng(clean, "clean.dng")?;
    for c in captures {
        dng(&c.dark, &format!("noisy_x{}.dng", c.ratio))?;
        dng(&c.restored[0], &format!("spc_x{}.dng", c.ratio))?;
        dng(&c.restored[1], &format!("pgrf_x{}.dng", c.ratio))?;
    }
    Ok(())
}

/// Run the demo: make the clean frame (before anything is loaded or
/// written), load the models with `load`, create the output folder, then
/// capture, restore, score and write, reporting to the progress `start`
/// makes once the work begins (one step for the reference, three per
/// ratio, one for the files).
pub fn run<P: Progress>(
    cfg: &DemoConfig<'_>,
    load: impl FnOnce() -> Result<Models, BoxError>,
    start: impl FnOnce() -> P,
) -> Result<Demo, DemoError> {
    let t0 = Instant::now();
    let Clean { frame: clean, what } = scene::clean_frame(&cfg.scene, cfg.seed)?;
    let models = load().map_err(DemoError::Models)?;
    let profile = CameraProfile::built_in("sony-a7s2").ok_or(DemoError::NoProfile("sony-a7s2"))?;
    if !cfg.output.is_dir() {
        std::fs::create_dir(&cfg.output).map_err(|source| DemoError::Folder {
            path: cfg.output.clone(),
            source,
        })?;
    }
    let progress = start();
    progress.start(2 + 3 * RATIOS.len() as u64, "steps");
    let bench = Bench {
        clean: &clean,
        reference: pack_normalized(&clean, true)?,
        models: &models,
        profile,
        seed: cfg.seed,
        // Tiles as `pgrf enhance` chooses them (memory, and the file's
        // cap).
        tiling: Tiling {
            tile: cfg.tile,
            overlap: None,
            seed: cfg.seed,
            device: DeviceKind::Cpu,
            kernels: cfg.kernels,
        },
    };
    progress.advance(1);
    let captures = (0..RATIOS.len())
        .map(|k| bench.capture(k, &progress))
        .collect::<Result<Vec<_>, _>>()?;
    progress.message("writing DNGs and the picture");
    write_dngs(&cfg.output, &clean, &captures)?;
    let picture = cfg.output.join("demo.png");
    picture::write_picture(&picture, &clean, &captures, cfg.scene.is_photo())?;
    progress.advance(1);
    progress.finish();
    Ok(Demo {
        what,
        models: [
            describe_method(models.spc.as_ref()),
            describe_method(models.pgrf.as_ref()),
        ],
        protocol: Protocol::eld(false),
        captures: captures
            .iter()
            .map(|c| CaptureScores {
                ratio: c.ratio,
                scores: c.scores.clone(),
            })
            .collect(),
        picture,
        seconds: t0.elapsed().as_secs_f64(),
    })
}
