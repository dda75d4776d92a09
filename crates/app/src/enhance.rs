//! `pgrf enhance`'s recipe for one file: open the dark photo, find the
//! exposure ratio, apply a calibration (dark shading, defect correction;
//! pgrf-calib's [`Calibration::prepare_light`]), restore it tile by tile,
//! write the linear DNG (or FITS: [`pgrf_raw::write_frame`] by `-o`'s
//! name) and the sRGB preview, and report what was done.
//!
//! A monochrome photo is restored too, by the same packing: its 2x2 blocks
//! become four planes, each a half-resolution image of the same scene with
//! the same per-pixel noise physics (shot and read noise per photosite, row
//! noise along the sensor's rows), which is what the four-channel Bayer
//! networks learned to denoise; only the colour differences between planes
//! are absent, as in a grey scene. Unpacking gives back the full-resolution
//! frame, written as a one-sample LinearRaw DNG (how DNG stores a sensor
//! without a colour filter) or a FITS image without a Bayer pattern. Which files go where: [`jobs::plan_jobs`]; many
//! files, shards, skipping and the manifest: [`batch::run_batch`]; the
//! flags: [`flags::EnhanceFlags`] (the `clap` feature).

use pgrf_calib::light::LightError;
use pgrf_calib::{CalibError, Calibration};
use pgrf_core::Progress;
use pgrf_nn::infer::prepare::{auto_ratio, ratio_from_exposure};
use pgrf_nn::infer::restorer::describe_sampler;
use pgrf_nn::infer::{restore_frame, Restore, Tiling};
use pgrf_nn::NnError;
use pgrf_noise::lookup::{find_noise, FrameNoise, KnownNoise, NoiseFlag};
use pgrf_raw::{render_preview, write_frame, DngOptions, PreviewOptions, RawError, RawFrame};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

pub mod batch;
#[cfg(feature = "clap")]
pub mod flags;
pub mod jobs;

/// An error from outside this crate (opening an input, loading models),
/// kept whole with its chain of causes.
pub type BoxError = Box<dyn std::error::Error + Send + Sync>;

/// Why a file could not be enhanced.
#[derive(Debug, thiserror::Error)]
pub enum EnhanceError {
    /// The input could not be opened (the opener's error, unchanged).
    #[error(transparent)]
    Open(BoxError),
    /// The calibration file could not be read.
    #[error("--calib")]
    LoadCalibration(#[source] Box<CalibError>),
    /// The calibration does not fit the photo.
    #[error("--calib {}", path.display())]
    Calibration {
        /// The calibration file.
        path: PathBuf,
        /// How it does not fit.
        #[source]
        source: Box<LightError>,
    },
    /// The calibration's dark shading for the photo's exposure time.
    #[error(transparent)]
    Shading(Box<CalibError>),
    /// The ratio from the exposure, or the restoration.
    #[error(transparent)]
    Network(#[from] NnError),
    /// The frame's noise parameters could not be found (a noise-aware
    /// model needs them).
    #[error("noise parameters: {0}")]
    Noise(pgrf_noise::NoiseError),
    /// The DNG (or FITS file) or the preview could not be made or written.
    #[error(transparent)]
    Write(#[from] RawError),
    /// Enhancing the file panicked (a bug, in pgrf or a library it calls):
    /// the batch records it as this file's failure and goes on.
    #[error(transparent)]
    Panicked(#[from] pgrf_core::panic_guard::Panicked),
}

/// How bright the result is made.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RatioChoice {
    /// Metered from the frame: its mean level brought to a fixed target
    /// ([`pgrf_nn::infer::prepare::auto_ratio`]); `--ratio auto`, and the
    /// default when neither a ratio nor a target exposure is given.
    Auto,
    /// The input is multiplied by this exposure ratio.
    Fixed(f32),
    /// Brightened to this exposure: target / the file's exposure time (x
    /// `iso` / the file's ISO when given).
    TargetExposure {
        /// The target exposure in seconds.
        seconds: f64,
        /// The target exposure's ISO (None: the file's).
        iso: Option<u32>,
    },
}

/// A calibration and the file it came from (named in its errors).
pub struct CalibrationFile {
    /// The file.
    pub path: PathBuf,
    /// Its contents.
    pub calibration: Calibration,
}

/// How every file of a run is enhanced.
pub struct EnhanceConfig {
    /// The exposure ratio, or how to find it.
    pub ratio: RatioChoice,
    /// Subtract this calibration's dark shading and correct its defects.
    pub calib: Option<CalibrationFile>,
    /// Apply a calibration of another camera or ISO anyway.
    pub force: bool,
    /// Tiles, start-noise seed and device.
    pub tiling: Tiling,
    /// The user's noise parameters (`--noise`), for a noise-aware model.
    pub noise: Option<NoiseFlag>,
    /// Subtract the black level measured on a file's masked pixels instead
    /// of its metadata's, when it has them and no calibration is given
    /// ([`masked_black`]); false when the user set the black level.
    pub masked_black: bool,
    /// darktable's noiseprofiles.json for the noise lookup (None:
    /// darktable's install is searched).
    pub darktable: Option<PathBuf>,
}

/// Where one input's results go.
#[derive(Clone, Debug, PartialEq)]
pub struct Job {
    /// The dark photo.
    pub input: PathBuf,
    /// The DNG (or FITS file) to write.
    pub output: PathBuf,
    /// The sRGB preview to write, if any.
    pub png: Option<PathBuf>,
}

/// What was done to one file (`pgrf enhance --json` prints it).
#[derive(Clone, Debug, Serialize)]
pub struct FileReport {
    /// The input.
    pub input: String,
    /// The DNG (or FITS file) written.
    pub output: String,
    /// The preview written.
    pub png: Option<String>,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// The exposure ratio applied.
    pub ratio: f32,
    /// How an automatic ratio was chosen (None when the user gave it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ratio_auto: Option<String>,
    /// The network and its sampler.
    pub method: String,
    /// Network evaluations per tile.
    pub nfe: usize,
    /// The largest tile's side in packed pixels.
    pub tile: usize,
    /// The tiles run.
    pub tiles: usize,
    /// Pixels the calibration's defect map replaced (cosmetic correction).
    pub defects_corrected: usize,
    /// Seconds for the file, opening included.
    pub seconds: f64,
    /// Where those seconds went.
    pub stages: StageSeconds,
    /// The process's peak resident memory so far.
    pub peak_rss_mib: Option<f64>,
    /// The noise parameters a noise-aware model was told, and their
    /// source (None for a model that is not told).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub noise: Option<String>,
    /// The black level subtracted when it was measured on the file's
    /// masked pixels, and where (None: the metadata's or the calibration's).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub black: Option<String>,
}

impl FileReport {
    /// What was written, on one line (`pgrf enhance` prints it).
    pub fn line(&self) -> String {
        let plural = if self.tiles == 1 { "" } else { "s" };
        let png = (self.png.as_ref())
            .map(|p| format!(" and {p}"))
            .unwrap_or_default();
        let defects = match self.defects_corrected {
            0 => String::new(),
            n => format!(", {n} defective pixels corrected from their neighbours"),
        };
        let noise = (self.noise.as_ref())
            .map(|n| format!("; noise {n}"))
            .unwrap_or_default();
        let auto = (self.ratio_auto.as_ref())
            .map(|a| format!(" ({a})"))
            .unwrap_or_default();
        let black = (self.black.as_ref())
            .map(|b| format!("; black {b}"))
            .unwrap_or_default();
        format!(
            "wrote {}{png}: {}x{}, ratio {:.1}{auto}, {} tile{plural} of {}, {:.1} s{defects}{black}{noise}",
            self.output, self.width, self.height, self.ratio, self.tiles, self.tile, self.seconds,
        )
    }
}

/// Seconds each stage of enhancing one file took (`pgrf enhance --json`;
/// BENCHMARKS.md's 24 MP table).
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct StageSeconds {
    /// Decoding the file and checking its size against memory.
    pub decode: f64,
    /// The calibration, the masked black, the ratio and the noise lookup.
    pub prepare: f64,
    /// The network over the tiles, packing and unpacking included.
    pub network: f64,
    /// Encoding and writing the DNG (or FITS file).
    pub write: f64,
    /// Rendering and writing the preview.
    pub preview: f64,
}

/// Seconds since `t`, and `t` moved to now.
fn lap(t: &mut Instant) -> f64 {
    let s = t.elapsed().as_secs_f64();
    *t = Instant::now();
    s
}

/// The network and its sampler, in one phrase ("SID U-Net ... (one pass)").
pub fn describe_method(restorer: &dyn Restore) -> String {
    format!(
        "{} ({})",
        restorer.meta().arch.describe(),
        describe_sampler(restorer)
    )
}

/// The exposure ratio of `frame` as `choice` says (an automatic one
/// metered after the calibration's `dark` shading), and how an automatic
/// one was chosen.
fn ratio_of(
    frame: &RawFrame,
    dark: Option<&ndarray::Array3<f32>>,
    choice: RatioChoice,
) -> Result<(f32, Option<String>), NnError> {
    match choice {
        RatioChoice::Fixed(r) => Ok((r, None)),
        RatioChoice::TargetExposure { seconds, iso } => {
            Ok((ratio_from_exposure(frame, seconds, iso)?, None))
        }
        RatioChoice::Auto => {
            let a = auto_ratio(frame, dark)?;
            Ok((a.ratio, Some(a.describe())))
        }
    }
}

/// The calibration's dark shading for `frame` (its defects corrected in
/// place), and how many defects were corrected.
fn calibrate(
    cfg: &EnhanceConfig,
    frame: &mut RawFrame,
) -> Result<(Option<ndarray::Array3<f32>>, usize), EnhanceError> {
    let Some(c) = &cfg.calib else {
        return Ok((None, 0));
    };
    match c.calibration.prepare_light(frame, cfg.force) {
        Ok(p) => Ok((Some(p.dark_dn), p.defects_corrected)),
        Err(LightError::Shading(e)) => Err(EnhanceError::Shading(Box::new(e))),
        Err(source) => Err(EnhanceError::Calibration {
            path: c.path.clone(),
            source: Box::new(source),
        }),
    }
}

/// Enhance `job.input` with `restorer`: opened by `open`, prepared as `cfg`
/// says, restored (`start` is called once the file is ready, and the
/// progress it returns hears the tiles), written to `job.output` (and
/// `job.png`).
pub fn enhance_file<P: Progress>(
    cfg: &EnhanceConfig,
    restorer: &dyn Restore,
    job: &Job,
    open: impl FnOnce(&Path) -> Result<RawFrame, BoxError>,
    start: impl FnOnce() -> P,
) -> Result<FileReport, EnhanceError> {
    let t0 = Instant::now();
    let (mut t, mut stages) = (t0, StageSeconds::default());
    let mut frame = open(&job.input).map_err(EnhanceError::Open)?;
    pgrf_nn::infer::memory::check_frame(
        restorer,
        &job.input,
        (frame.width, frame.height),
        cfg.tiling.tile,
        cfg.tiling.device,
        job.png.is_some(),
    )?;
    stages.decode = lap(&mut t);
    let (dark, defects_corrected) = calibrate(cfg, &mut frame)?;
    let black = (cfg.masked_black && cfg.calib.is_none())
        .then(|| masked_black(&mut frame))
        .flatten();
    let (ratio, ratio_auto) = ratio_of(&frame, dark.as_ref(), cfg.ratio)?;
    let noise = match restorer.meta().arch.conditioning().needs_level() {
        true => Some(frame_noise(cfg, &frame)?),
        false => None,
    };
    let level = noise
        .as_ref()
        .map(|n| crate::array::level_of(n, &frame, ratio));
    stages.prepare = lap(&mut t);
    let progress = start();
    let mut restored = restore_frame(
        restorer,
        &frame,
        ratio,
        dark.as_ref(),
        level,
        &cfg.tiling,
        &progress,
    )?;
    let (tiles, tile) = (restored.packed.plan.count(), restored.packed.tile_side());
    // The input's NoiseProfile describes the noisy input; what noise a
    // network leaves is not known, so the output states none.
    restored.frame.noise_profile = None;
    stages.network = lap(&mut t);
    write_frame(&restored.frame, &job.output, &DngOptions::default())?;
    stages.write = lap(&mut t);
    if let Some(png) = &job.png {
        render_preview(&restored.frame, &PreviewOptions::default())?.write_png(png, 8)?;
    }
    stages.preview = lap(&mut t);
    Ok(FileReport {
        input: job.input.display().to_string(),
        output: job.output.display().to_string(),
        png: job.png.as_ref().map(|p| p.display().to_string()),
        width: frame.width,
        height: frame.height,
        ratio,
        ratio_auto,
        method: describe_method(restorer),
        nfe: restorer.nfe(),
        tile,
        tiles,
        defects_corrected,
        seconds: t0.elapsed().as_secs_f64(),
        stages,
        peak_rss_mib: pgrf_core::mem::peak_rss_mib(),
        noise: noise.map(|n| n.to_string()),
        black,
    })
}

/// Largest difference between the masked pixels' level and the metadata's
/// black that is taken as the capture's offset, as a share of the range:
/// ELD's colour bias is a few DN; a masked area tens of DN off is more
/// likely not dark (a file's claim) than an offset.
pub const MASKED_BLACK_REACH: f32 = 0.02;

/// Take the black level of an uncalibrated `frame` from its masked pixels
/// ([`pgrf_raw::masked`]) when it has them and they lie within
/// [`MASKED_BLACK_REACH`] of the metadata's; says what was used, and when
/// they were not used, why.
pub fn masked_black(frame: &mut RawFrame) -> Option<String> {
    let m = frame.masked.as_ref()?;
    let range = frame.white as f32 - frame.black.iter().copied().fold(0.0, f32::max);
    let fmt = pgrf_raw::masked::levels_text;
    let off = m
        .level
        .iter()
        .zip(frame.black)
        .map(|(l, b)| (l - b).abs())
        .fold(0.0, f32::max);
    if off > MASKED_BLACK_REACH * range {
        return Some(format!(
            "{} DN from the metadata: the masked pixels ({}) read {} DN, {off:.0} DN away, not used",
            fmt(frame.black),
            m.source.describe(),
            fmt(m.level)
        ));
    }
    let line = format!(
        "{} DN measured on {} ({} px per plane; metadata {})",
        fmt(m.level),
        m.source.describe(),
        m.pixels,
        fmt(frame.black)
    );
    frame.black = m.level;
    Some(line)
}

/// The frame's noise parameters for a noise-aware model: the calibration's,
/// the user's, or what [`find_noise`] finds for the file.
fn frame_noise(cfg: &EnhanceConfig, frame: &RawFrame) -> Result<FrameNoise, EnhanceError> {
    let calibration = cfg.calib.as_ref().map(|c| {
        let m = &c.calibration.meta;
        (c.path.clone(), m.k, m.read_sigma_median, m.row_sigma)
    });
    let known = KnownNoise {
        calibration,
        flag: cfg.noise,
        darktable: cfg.darktable.clone(),
    };
    find_noise(frame, &known).map_err(EnhanceError::Noise)
}
