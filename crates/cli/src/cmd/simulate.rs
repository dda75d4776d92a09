//! `pgrf simulate-sensor`: bias, dark and flat stacks from a virtual sensor
//! with known per-pixel truth, to test calibration end to end.

use anyhow::{bail, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use pgrf_noise::mapfile::write_maps;
use pgrf_noise::sensor::{SensorSpec, VirtualSensor};
use pgrf_noise::DarkLaw;
use pgrf_raw::{write_dng, write_fits_frame, DngOptions};
use std::path::PathBuf;

/// Dark exposures (s) and flat levels (electrons, exposure s) of the stacks.
pub const DARK_EXPOSURES: [f32; 3] = [1.0, 4.0, 16.0];
pub const FLAT_LEVELS: [(f32, f32); 2] = [(2000.0, 0.01), (8000.0, 0.04)];
pub const BIAS_EXPOSURE: f32 = 1.0 / 8000.0;

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

#[derive(Args, Debug)]
pub struct SimulateArgs {
    /// Sensor preset: `a7s2-iso<ISO>` (published A7S2 gain, read and row noise at that ISO).
    #[arg(long, default_value = "a7s2-iso1600")]
    pub preset: String,
    /// Frames per stack (bias) and per exposure (dark, flat).
    #[arg(long, default_value_t = 32)]
    pub frames: usize,
    /// Output folder (created): bias/, dark/, flat/, truth.safetensors.
    #[arg(short, long)]
    pub output: PathBuf,
    #[arg(long, default_value_t = 1024)]
    pub width: usize,
    #[arg(long, default_value_t = 768)]
    pub height: usize,
    /// Time law of the simulated dark current.
    #[arg(long, default_value = "sqrt")]
    pub dark_law: DarkLaw,
    /// Dark offset c in electrons: charge every exposed frame has on top of the law (y = a g(t) + c), absent from the bias frames.
    #[arg(long, default_value_t = 0.0)]
    pub dark_offset: f32,
    /// Exposure times of the dark stack, seconds (comma separated).
    #[arg(long, value_delimiter = ',', default_values_t = DARK_EXPOSURES)]
    pub dark_exposures: Vec<f32>,
    /// Frames per dark exposure (default: --frames); one is how dark ladders are usually shot.
    #[arg(long)]
    pub dark_frames: Option<usize>,
    /// Flat lamp drift: each flat frame of a level is this fraction brighter than the one before (0.003 = 0.3 % per frame).
    #[arg(long, default_value_t = 0.0)]
    pub lamp_drift: f32,
    /// Whole-frame offset drift: each frame's offset is drawn with this standard deviation, DN.
    #[arg(long, default_value_t = 0.0)]
    pub frame_offset: f32,
    /// Capture temperature written into every frame, degrees C.
    #[arg(long, allow_hyphen_values = true)]
    pub temperature: Option<f32>,
    /// A monochrome sensor (no colour filter, as an astronomy CCD).
    #[arg(long)]
    pub mono: bool,
    /// Write the frames as FITS (16-bit, as astronomy cameras do) instead of DNG.
    #[arg(long)]
    pub fits: bool,
    /// Flat shading: the light lost at the corners (0.2 = 20 %), as a lens's vignetting.
    #[arg(long, default_value_t = 0.0)]
    pub vignetting: f32,
    /// Which stacks to write (comma separated): bias, dark, flat.
    #[arg(long, value_delimiter = ',', default_value = "bias,dark,flat")]
    pub stacks: Vec<String>,
    /// Seed of the frames (the sensor's own maps have a fixed seed per preset).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

pub fn run(a: &SimulateArgs) -> Result<()> {
    if a.frames < 2 {
        bail!("--frames must be at least 2 (per-pixel variance needs two frames)");
    }
    let dark_frames = a.dark_frames.unwrap_or(a.frames);
    if dark_frames == 0 || dark_frames > 100_000 {
        bail!("--dark-frames must be between 1 and 100000, got {dark_frames}");
    }
    if !(a.dark_offset.is_finite() && (0.0..=1e6).contains(&a.dark_offset)) {
        bail!(
            "--dark-offset must be between 0 and 1e6 electrons, got {}",
            a.dark_offset
        );
    }
    if !(a.lamp_drift.is_finite() && a.lamp_drift.abs() <= 0.1) {
        bail!(
            "--lamp-drift must be a fraction between -0.1 and 0.1 per frame, got {}",
            a.lamp_drift
        );
    }
    if !(a.frame_offset.is_finite() && (0.0..=1000.0).contains(&a.frame_offset)) {
        bail!(
            "--frame-offset must be between 0 and 1000 DN, got {}",
            a.frame_offset
        );
    }
    if let Some(t) = a.temperature {
        if !(t.is_finite() && (-273.0..=200.0).contains(&t)) {
            bail!("--temperature must be between -273 and 200 °C, got {t}");
        }
    }
    if !(a.vignetting.is_finite() && (0.0..0.9).contains(&a.vignetting)) {
        bail!(
            "--vignetting must be a fraction between 0 and 0.9, got {}",
            a.vignetting
        );
    }
    if a.dark_exposures.is_empty()
        || a.dark_exposures
            .iter()
            .any(|t| !(t.is_finite() && *t > 0.0 && *t <= 1e5))
    {
        bail!("--dark-exposures must be times in (0, 1e5] seconds");
    }
    super::make_dataset::check_frame_memory(
        &format!("--width {} --height {}", a.width, a.height),
        a.width,
        a.height,
        128.0,
    )?;
    // Before any work: the output folder's parent exists, the output is not
    // a file, and no stack folder already holds frames (old frames would
    // join the new stacks and calibrate a sensor that never existed).
    if a.output.exists() && !a.output.is_dir() {
        bail!("-o {} is a file; give a folder", a.output.display());
    }
    crate::output::require_parent_dir(&a.output).map_err(|e| anyhow::anyhow!("-o {e}"))?;
    for sub in ["bias", "dark", "flat"] {
        let dir = a.output.join(sub);
        if std::fs::read_dir(&dir).is_ok_and(|mut d| d.next().is_some()) {
            bail!(
                "-o {}: {} already holds frames; give a new folder",
                a.output.display(),
                dir.display()
            );
        }
    }
    let mut spec = SensorSpec::preset(&a.preset)?;
    spec.width = a.width;
    spec.height = a.height;
    spec.dark_law = a.dark_law;
    spec.dark_offset = a.dark_offset;
    spec.frame_offset_sigma = a.frame_offset;
    spec.vignetting = a.vignetting;
    spec.mono = a.mono;
    spec.temperature_c = a.temperature;
    let sensor = VirtualSensor::new(spec)?;
    for s in &a.stacks {
        if !["bias", "dark", "flat"].contains(&s.as_str()) {
            bail!("unknown stack '{s}' in --stacks (bias, dark, flat)");
        }
    }
    let want = |s: &str| a.stacks.iter().any(|x| x == s);
    for sub in ["bias", "dark", "flat"].into_iter().filter(|s| want(s)) {
        std::fs::create_dir_all(a.output.join(sub)).map_err(|e| {
            anyhow::anyhow!(
                "{}: cannot create folder: {e}",
                a.output.join(sub).display()
            )
        })?;
    }
    let total = a.frames * (want("bias") as usize + want("flat") as usize * FLAT_LEVELS.len())
        + want("dark") as usize * dark_frames * a.dark_exposures.len();
    let bar = ProgressBar::new(total as u64).with_style(
        ProgressStyle::with_template(
            "{spinner} simulating {pos}/{len} frames [{bar:30}] {per_sec} eta {eta}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    let mut seed = a.seed.wrapping_mul(1_000_003);
    let mut write = |sub: &str, tag: &str, n: usize, electrons: f32, t: f32| -> Result<()> {
        for i in 0..n {
            seed = seed.wrapping_add(1);
            let lamp = if electrons > 0.0 {
                (1.0 + a.lamp_drift * i as f32).max(0.0)
            } else {
                1.0
            };
            let f = sensor.frame(electrons * lamp, t, seed)?;
            let ext = if a.fits { "fits" } else { "dng" };
            let path = a.output.join(sub).join(format!("{tag}_{i:04}.{ext}"));
            if a.fits {
                write_fits_frame(&f, &path)?;
            } else {
                write_dng(&f, &path, &DngOptions::default())?;
            }
            bar.inc(1);
        }
        Ok(())
    };
    if want("bias") {
        write("bias", "bias", a.frames, 0.0, BIAS_EXPOSURE)?;
    }
    if want("dark") {
        for &t in &a.dark_exposures {
            write("dark", &format!("dark_{t}s"), dark_frames, 0.0, t)?;
        }
    }
    if want("flat") {
        for (e, t) in flat_levels(&sensor.spec) {
            write("flat", &format!("flat_{e:.0}e"), a.frames, e, t)?;
        }
    }
    bar.finish_and_clear();
    let maps: Vec<(&str, pgrf_raw::ndarray::ArrayView3<f32>)> = sensor
        .truth_maps()
        .into_iter()
        .map(|(n, m)| (n, m.view()))
        .collect();
    write_maps(
        &a.output.join("truth.safetensors"),
        &maps,
        &sensor.truth_meta(),
    )?;
    eprintln!(
        "wrote {total} frames ({}x{}, ISO {}, K {:.4} DN/e-, {} dark law) and truth.safetensors to {}",
        a.width,
        a.height,
        sensor.spec.iso,
        sensor.spec.k,
        match a.dark_law {
            DarkLaw::Sqrt => "sqrt",
            DarkLaw::Linear => "linear",
        },
        a.output.display()
    );
    Ok(())
}
