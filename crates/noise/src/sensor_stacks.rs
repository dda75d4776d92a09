//! Calibration stacks of a [`VirtualSensor`]: bias, dark and flat frames
//! written as DNG or FITS, with the per-pixel truth that generated them in
//! `truth.safetensors` beside them (`pgrf simulate-sensor`). It is how
//! calibration is tested end to end: every estimate of a calibration run on
//! these folders can be compared with the map it should find.
//!
//! [`write_stacks`] is the whole recipe: check the settings, build the
//! sensor, write the frames, write the truth. The frames of one config and
//! seed are the same bytes on every run.

use crate::error::NoiseError;
use crate::mapfile::write_maps;
use crate::profile::DarkLaw;
use crate::sensor::{SensorSpec, VirtualSensor};
use pgrf_core::Progress;
use pgrf_raw::{write_frame, DngOptions, FrameFormat, RawError};
use std::path::{Path, PathBuf};

/// Dark exposures (s) of the dark stack unless the config gives others.
pub const DARK_EXPOSURES: [f32; 3] = [1.0, 4.0, 16.0];
/// Flat levels (electrons, exposure s) before [`flat_levels`] scales them.
pub const FLAT_LEVELS: [(f32, f32); 2] = [(2000.0, 0.01), (8000.0, 0.04)];
/// Exposure of the bias frames, s.
pub const BIAS_EXPOSURE: f32 = 1.0 / 8000.0;
/// The stacks a config may ask for, in the order they are written.
pub const STACKS: [&str; 3] = ["bias", "dark", "flat"];

/// The flat levels for this sensor: [`FLAT_LEVELS`] where the brighter one
/// stays below 80 % of the DN range (ISO 1600 and below on the A7S2), else
/// both scaled down by one factor so it does. At ISO 3200 and above the
/// fixed electron counts would clip every pixel, and a clipped flat gives a
/// wrong (even negative) gain.
pub fn flat_levels(spec: &SensorSpec) -> [(f32, f32); 2] {
    let range = spec.dn_range();
    let brightest = FLAT_LEVELS[1].0 * spec.k;
    let scale = (0.8 * range / brightest).min(1.0);
    FLAT_LEVELS.map(|(e, t)| (e * scale, t))
}

/// Everything [`write_stacks`] needs: the sensor, the stacks and where they go.
#[derive(Clone, Debug)]
pub struct StacksConfig {
    /// Sensor preset ([`SensorSpec::preset`], `a7s2-iso<ISO>`).
    pub preset: String,
    /// Frames of the bias stack and per flat level.
    pub frames: usize,
    /// Frames per dark exposure (None: `frames`).
    pub dark_frames: Option<usize>,
    /// Output folder (created): bias/, dark/, flat/, truth.safetensors.
    pub output: PathBuf,
    /// Frame width, pixels.
    pub width: usize,
    /// Frame height, pixels.
    pub height: usize,
    /// Time law of the dark current.
    pub dark_law: DarkLaw,
    /// Dark offset c, electrons (absent from the bias frames).
    pub dark_offset: f32,
    /// Exposure times of the dark stack, s.
    pub dark_exposures: Vec<f32>,
    /// Each flat frame of a level is this fraction brighter than the one before.
    pub lamp_drift: f32,
    /// Standard deviation of each frame's whole-frame offset, DN.
    pub frame_offset: f32,
    /// Capture temperature written into every frame, degrees C.
    pub temperature: Option<f32>,
    /// A monochrome sensor (no colour filter).
    pub mono: bool,
    /// Light lost at the corners of the flats (0.2 = 20 %).
    pub vignetting: f32,
    /// Temperature rise that doubles the dark current, degrees C (0: none;
    /// the preset's dark rate holds at 0 degrees C).
    pub dark_doubling: f32,
    /// Read noise with heavy tails: Tukey-lambda of this lambda (-0.5 <
    /// lambda < 0.5; negative is heavier than Gaussian) instead of Gaussian.
    pub read_tails: Option<f32>,
    /// Random telegraph pixels: their share (0..0.1) and the jump between
    /// their two states, DN.
    pub rts: Option<(f32, f32)>,
    /// The file format of the frames.
    pub format: FrameFormat,
    /// Which stacks to write, by name ([`STACKS`]).
    pub stacks: Vec<String>,
    /// Seed of the frames (the sensor's maps have a fixed seed per preset).
    pub seed: u64,
}

/// What [`write_stacks`] wrote.
#[derive(Clone, Debug)]
pub struct StacksWritten {
    /// Frames written, all stacks together.
    pub frames: usize,
    /// The sensor that made them (its ISO and gain K for the summary).
    pub spec: SensorSpec,
}

/// Why stacks were not written. The messages name the `pgrf
/// simulate-sensor` flag at fault, as the command has always printed them.
#[derive(Debug, thiserror::Error)]
pub enum StacksError {
    /// Fewer than two frames per stack, or more than 100000.
    #[error(
        "--frames must be between 2 (per-pixel variance needs two frames) and 100000, got {frames}"
    )]
    TooFewFrames {
        /// Frames asked for.
        frames: usize,
    },
    /// Frames per dark exposure outside 1..=100000.
    #[error("--dark-frames must be between 1 and 100000, got {frames}")]
    DarkFrames {
        /// Frames asked for.
        frames: usize,
    },
    /// A dark offset outside 0..=1e6 electrons.
    #[error("--dark-offset must be between 0 and 1e6 electrons, got {electrons}")]
    DarkOffset {
        /// The offset given, electrons.
        electrons: f32,
    },
    /// A lamp drift outside -0.1..=0.1 per frame.
    #[error("--lamp-drift must be a fraction between -0.1 and 0.1 per frame, got {drift}")]
    LampDrift {
        /// The drift given.
        drift: f32,
    },
    /// A frame-offset spread outside 0..=1000 DN.
    #[error("--frame-offset must be between 0 and 1000 DN, got {dn}")]
    FrameOffset {
        /// The spread given, DN.
        dn: f32,
    },
    /// A temperature outside -273..=200 degrees C.
    #[error("--temperature must be between -273 and 200 °C, got {celsius}")]
    Temperature {
        /// The temperature given.
        celsius: f32,
    },
    /// A read-noise tail or telegraph setting out of range.
    #[error("{flag}: {message}")]
    NoiseSetting {
        /// The flag.
        flag: &'static str,
        /// What is wrong.
        message: String,
    },
    /// Vignetting outside 0..0.9.
    #[error("--vignetting must be a fraction between 0 and 0.9, got {fraction}")]
    Vignetting {
        /// The fraction given.
        fraction: f32,
    },
    /// No dark exposure, or one outside (0, 1e5] seconds.
    #[error("--dark-exposures must be times in (0, 1e5] seconds")]
    DarkExposures {
        /// The exposures given, s.
        exposures: Vec<f32>,
    },
    /// Frames of this size would not fit in memory.
    #[error("{0}; give a smaller size")]
    Memory(pgrf_core::mem::NoMemory),
    /// The output names a file, not a folder.
    #[error("-o {} is a file; give a folder", output.display())]
    OutputIsFile {
        /// The output.
        output: PathBuf,
    },
    /// The output folder's parent does not exist.
    #[error("-o {}: folder {} does not exist", output.display(), parent.display())]
    NoParentFolder {
        /// The output.
        output: PathBuf,
        /// Its missing parent.
        parent: PathBuf,
    },
    /// A stack folder already holds files, which would join the new stack.
    #[error("-o {}: {} already holds frames; give a new folder", output.display(), folder.display())]
    StackNotEmpty {
        /// The output.
        output: PathBuf,
        /// The stack folder that is not empty.
        folder: PathBuf,
    },
    /// A stack name that is not one of [`STACKS`].
    #[error("unknown stack '{name}' in --stacks (bias, dark, flat)")]
    UnknownStack {
        /// The name given.
        name: String,
    },
    /// A stack folder that could not be created.
    #[error("{}: cannot create folder: {error}", folder.display())]
    CreateFolder {
        /// The folder.
        folder: PathBuf,
        /// The operating system's error.
        error: std::io::Error,
    },
    /// The sensor preset or design was refused, or the truth not written.
    #[error(transparent)]
    Noise(#[from] NoiseError),
    /// A frame was not written.
    #[error(transparent)]
    Raw(#[from] RawError),
}

impl StacksConfig {
    /// Frames per dark exposure.
    pub fn dark_frames(&self) -> usize {
        self.dark_frames.unwrap_or(self.frames)
    }

    /// Refuse settings the sensor or calibration cannot use, before any work.
    fn check_settings(&self) -> Result<(), StacksError> {
        if !(2..=100_000).contains(&self.frames) {
            return Err(StacksError::TooFewFrames {
                frames: self.frames,
            });
        }
        let dark_frames = self.dark_frames();
        if dark_frames == 0 || dark_frames > 100_000 {
            return Err(StacksError::DarkFrames {
                frames: dark_frames,
            });
        }
        if !(self.dark_offset.is_finite() && (0.0..=1e6).contains(&self.dark_offset)) {
            return Err(StacksError::DarkOffset {
                electrons: self.dark_offset,
            });
        }
        if !(self.lamp_drift.is_finite() && self.lamp_drift.abs() <= 0.1) {
            return Err(StacksError::LampDrift {
                drift: self.lamp_drift,
            });
        }
        if !(self.frame_offset.is_finite() && (0.0..=1000.0).contains(&self.frame_offset)) {
            return Err(StacksError::FrameOffset {
                dn: self.frame_offset,
            });
        }
        if let Some(t) = self.temperature {
            if !(t.is_finite() && (-273.0..=200.0).contains(&t)) {
                return Err(StacksError::Temperature { celsius: t });
            }
        }
        self.check_noise_settings()?;
        if !(self.vignetting.is_finite() && (0.0..0.9).contains(&self.vignetting)) {
            return Err(StacksError::Vignetting {
                fraction: self.vignetting,
            });
        }
        if self.dark_exposures.is_empty()
            || self
                .dark_exposures
                .iter()
                .any(|t| !(t.is_finite() && *t > 0.0 && *t <= 1e5))
        {
            return Err(StacksError::DarkExposures {
                exposures: self.dark_exposures.clone(),
            });
        }
        pgrf_core::mem::check_fits(
            &format!("--width {} --height {}", self.width, self.height),
            self.width as f64 * self.height as f64 * 128.0,
        )
        .map_err(StacksError::Memory)
    }

    /// The dark current's doubling temperature, the read noise's tails and
    /// the random telegraph pixels, each within what a sensor has.
    fn check_noise_settings(&self) -> Result<(), StacksError> {
        let bad = |flag, message| Err(StacksError::NoiseSetting { flag, message });
        if !(self.dark_doubling.is_finite() && (0.0..=50.0).contains(&self.dark_doubling)) {
            return bad(
                "--dark-doubling",
                format!(
                    "the doubling temperature must be in 0..50 degrees C (0: none), got {}",
                    self.dark_doubling
                ),
            );
        }
        if let Some(l) = self
            .read_tails
            .filter(|l| !(l.is_finite() && l.abs() < 0.5))
        {
            return bad(
                "--read-tails",
                format!("lambda must lie strictly between -0.5 and 0.5 (finite variance), got {l}"),
            );
        }
        if let Some((f, a)) = self.rts {
            let fine = f.is_finite() && (0.0..=0.1).contains(&f);
            if !(fine && a.is_finite() && (0.0..=1000.0).contains(&a)) {
                return bad(
                    "--rts",
                    format!("the share must be in 0..0.1 and the jump in 0..1000 DN, got {f},{a}"),
                );
            }
        }
        Ok(())
    }

    /// Before any work: the output folder's parent exists, the output is
    /// not a file, and no stack folder already holds frames (old frames
    /// would join the new stacks and calibrate a sensor that never existed).
    fn check_output(&self) -> Result<(), StacksError> {
        let output = &self.output;
        if output.exists() && !output.is_dir() {
            return Err(StacksError::OutputIsFile {
                output: output.clone(),
            });
        }
        if let Some(parent) = output.parent().filter(|d| !d.as_os_str().is_empty()) {
            if !parent.is_dir() {
                return Err(StacksError::NoParentFolder {
                    output: output.clone(),
                    parent: parent.to_path_buf(),
                });
            }
        }
        for sub in STACKS {
            let folder = output.join(sub);
            if std::fs::read_dir(&folder).is_ok_and(|mut d| d.next().is_some()) {
                return Err(StacksError::StackNotEmpty {
                    output: output.clone(),
                    folder,
                });
            }
        }
        Ok(())
    }

    /// The virtual sensor of the preset with this config's design.
    fn sensor(&self) -> Result<VirtualSensor, StacksError> {
        let mut spec = SensorSpec::preset(&self.preset)?;
        spec.width = self.width;
        spec.height = self.height;
        spec.dark_law = self.dark_law;
        spec.dark_offset = self.dark_offset;
        spec.frame_offset_sigma = self.frame_offset;
        spec.vignetting = self.vignetting;
        spec.mono = self.mono;
        spec.temperature_c = self.temperature;
        spec.read_tukey_lambda = self.read_tails;
        spec.dark_doubling_c = self.dark_doubling;
        (spec.rts_fraction, spec.rts_amplitude) = self.rts.unwrap_or((0.0, 0.0));
        Ok(VirtualSensor::new(spec)?)
    }

    /// Whether stack `name` is asked for.
    fn wants(&self, name: &str) -> bool {
        self.stacks.iter().any(|x| x == name)
    }

    /// The stacks asked for, checked by name; their folders created.
    fn make_folders(&self) -> Result<(), StacksError> {
        if let Some(name) = self.stacks.iter().find(|s| !STACKS.contains(&s.as_str())) {
            return Err(StacksError::UnknownStack { name: name.clone() });
        }
        for sub in STACKS.into_iter().filter(|s| self.wants(s)) {
            let folder = self.output.join(sub);
            std::fs::create_dir_all(&folder)
                .map_err(|error| StacksError::CreateFolder { folder, error })?;
        }
        Ok(())
    }

    /// Frames the stacks asked for hold, all together.
    fn total_frames(&self) -> usize {
        self.frames
            * (self.wants("bias") as usize + self.wants("flat") as usize * FLAT_LEVELS.len())
            + self.wants("dark") as usize * self.dark_frames() * self.dark_exposures.len()
    }
}

/// The IMAGETYP of a frame of stack `sub` ("bias", "dark", "flat"), as
/// CCDSoft writes it.
fn image_type(sub: &str) -> &'static str {
    match sub {
        "bias" => "Bias Frame",
        "dark" => "Dark Frame",
        _ => "Flat Field",
    }
}

/// Writes one stack's frames after another, every frame with the next seed.
struct FrameWriter<'a> {
    config: &'a StacksConfig,
    sensor: &'a VirtualSensor,
    progress: &'a dyn Progress,
    seed: u64,
}

impl FrameWriter<'_> {
    /// `n` frames `TAG_0000.EXT`.. into folder `sub`, each with `electrons`
    /// of light (drifting with the lamp) and exposure `t`.
    fn stack(
        &mut self,
        sub: &str,
        tag: &str,
        n: usize,
        electrons: f32,
        t: f32,
    ) -> Result<(), StacksError> {
        let ext = self.config.format.extension();
        for i in 0..n {
            self.seed = self.seed.wrapping_add(1);
            let lamp = if electrons > 0.0 {
                (1.0 + self.config.lamp_drift * i as f32).max(0.0)
            } else {
                1.0
            };
            let mut f = self.sensor.frame(electrons * lamp, t, self.seed)?;
            if self.config.format == FrameFormat::Fits {
                // What CCDSoft and MaxIm DL state of each frame.
                f.fits = Some(pgrf_raw::FitsHeader {
                    row_order: Some(f.row_order()),
                    image_type: Some(image_type(sub).into()),
                    ..Default::default()
                });
            }
            let path = self
                .config
                .output
                .join(sub)
                .join(format!("{tag}_{i:04}.{ext}"));
            write_frame(&f, &path, &DngOptions::default())?;
            self.progress.advance(1);
        }
        Ok(())
    }
}

/// Check `config`, build its virtual sensor, write the stacks it asks for
/// (bias, then dark per exposure, then flat per level) into their folders
/// of `config.output`, and the sensor's truth maps to
/// `truth.safetensors` there. Nothing is written when a setting or the
/// output is refused.
pub fn write_stacks(
    config: &StacksConfig,
    progress: &dyn Progress,
) -> Result<StacksWritten, StacksError> {
    config.check_settings()?;
    config.check_output()?;
    let sensor = config.sensor()?;
    config.make_folders()?;
    let total = config.total_frames();
    progress.start(total as u64, "frames");
    let mut w = FrameWriter {
        config,
        sensor: &sensor,
        progress,
        seed: config.seed.wrapping_mul(1_000_003),
    };
    if config.wants("bias") {
        w.stack("bias", "bias", config.frames, 0.0, BIAS_EXPOSURE)?;
    }
    if config.wants("dark") {
        for &t in &config.dark_exposures {
            w.stack("dark", &format!("dark_{t}s"), config.dark_frames(), 0.0, t)?;
        }
    }
    if config.wants("flat") {
        for (e, t) in flat_levels(&sensor.spec) {
            w.stack("flat", &format!("flat_{e:.0}e"), config.frames, e, t)?;
        }
    }
    progress.finish();
    write_truth(&sensor, &config.output.join("truth.safetensors"))?;
    Ok(StacksWritten {
        frames: total,
        spec: sensor.spec,
    })
}

/// The sensor's per-pixel truth maps and design, as a map file.
fn write_truth(sensor: &VirtualSensor, path: &Path) -> Result<(), StacksError> {
    let maps: Vec<(&str, ndarray::ArrayView3<f32>)> = sensor
        .truth_maps()
        .into_iter()
        .map(|(n, m)| (n, m.view()))
        .collect();
    Ok(write_maps(path, &maps, &sensor.truth_meta())?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use pgrf_core::NoProgress;

    fn config(output: PathBuf) -> StacksConfig {
        StacksConfig {
            preset: "a7s2-iso1600".into(),
            frames: 2,
            dark_frames: Some(1),
            output,
            width: 16,
            height: 12,
            dark_law: DarkLaw::Sqrt,
            dark_offset: 0.0,
            dark_exposures: vec![1.0, 2.5],
            lamp_drift: 0.0,
            frame_offset: 0.0,
            temperature: None,
            mono: false,
            vignetting: 0.0,
            dark_doubling: 0.0,
            read_tails: None,
            rts: None,
            format: FrameFormat::Fits,
            stacks: vec!["bias".into(), "dark".into(), "flat".into()],
            seed: 3,
        }
    }

    fn scratch(name: &str) -> PathBuf {
        let d =
            std::env::temp_dir().join(format!("pgrf-noise-stacks-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
        let mut out = Vec::new();
        for sub in STACKS {
            let Ok(entries) = std::fs::read_dir(dir.join(sub)) else {
                continue;
            };
            for e in entries {
                let p = e.unwrap().path();
                let name = format!("{sub}/{}", p.file_name().unwrap().to_string_lossy());
                out.push((name, std::fs::read(&p).unwrap()));
            }
        }
        out.sort();
        out
    }

    /// Every stack asked for, named by tag and index, the truth beside
    /// them; the same config writes the same bytes.
    #[test]
    fn stacks_are_named_counted_and_reproducible() {
        let root = scratch("ok");
        let (a, b) = (root.join("a"), root.join("b"));
        let written = write_stacks(&config(a.clone()), &NoProgress).unwrap();
        write_stacks(&config(b.clone()), &NoProgress).unwrap();
        // 2 bias + 2 x 1 dark + 2 levels x 2 flat.
        assert_eq!(written.frames, 8);
        let (fa, fb) = (files(&a), files(&b));
        let names: Vec<&str> = fa.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(
            names,
            [
                "bias/bias_0000.fits",
                "bias/bias_0001.fits",
                "dark/dark_1s_0000.fits",
                "dark/dark_2.5s_0000.fits",
                "flat/flat_2000e_0000.fits",
                "flat/flat_2000e_0001.fits",
                "flat/flat_8000e_0000.fits",
                "flat/flat_8000e_0001.fits",
            ]
        );
        assert_eq!(fa, fb);
        assert!(a.join("truth.safetensors").is_file());
        std::fs::remove_dir_all(&root).unwrap();
    }

    /// Refused settings and outputs write nothing.
    #[test]
    fn refusals_name_the_setting_and_write_nothing() {
        let root = scratch("refused");
        let out = root.join("x");
        let mut c = config(out.clone());
        c.frames = 1;
        assert!(matches!(
            write_stacks(&c, &NoProgress),
            Err(StacksError::TooFewFrames { frames: 1 })
        ));
        let mut c = config(out.clone());
        c.stacks.push("lights".into());
        let e = write_stacks(&c, &NoProgress).unwrap_err();
        assert!(
            matches!(&e, StacksError::UnknownStack { name } if name == "lights"),
            "{e}"
        );
        assert!(!out.exists());
        let c = config(root.join("no/such/folder"));
        assert!(matches!(
            write_stacks(&c, &NoProgress),
            Err(StacksError::NoParentFolder { .. })
        ));
        // A second run into the same folder would mix two sensors' frames.
        let mut c = config(out.clone());
        c.stacks = vec!["bias".into()];
        write_stacks(&c, &NoProgress).unwrap();
        let e = write_stacks(&c, &NoProgress).unwrap_err();
        assert!(
            e.to_string()
                .ends_with("already holds frames; give a new folder"),
            "{e}"
        );
        std::fs::remove_dir_all(&root).unwrap();
    }
}
