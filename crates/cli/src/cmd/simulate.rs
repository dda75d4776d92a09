//! `pgrf simulate-sensor`: bias, dark and flat stacks from a virtual sensor
//! with known per-pixel truth, to test calibration end to end. The recipe is
//! `pgrf_noise::sensor_stacks`; this turns the flags into its config.

use crate::progress::Bar;
use anyhow::Result;
use clap::Args;
use pgrf_noise::sensor_stacks::{write_stacks, StacksConfig, DARK_EXPOSURES};
use pgrf_noise::DarkLaw;
use pgrf_raw::FrameFormat;
use std::path::PathBuf;

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
    /// Temperature rise that doubles the dark current, degrees C (0: none): the preset's dark rate holds at 0 degrees C, and frames at --temperature T have 2^(T / DOUBLING) times it.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub dark_doubling: f32,
    /// Read noise with heavy tails: Tukey-lambda of this lambda (ELD's read-noise law; -0.2 is heavier than Gaussian; -0.5 < lambda < 0.5) at each pixel's sigma as its scale, instead of Gaussian.
    #[arg(long, allow_hyphen_values = true)]
    pub read_tails: Option<f32>,
    /// Random telegraph pixels: SHARE,JUMP (e.g. 0.002,40): that share of the pixels jumps between two levels JUMP DN apart, drawn anew every frame.
    #[arg(long, value_parser = parse_rts)]
    pub rts: Option<(f32, f32)>,
    /// Which stacks to write (comma separated): bias, dark, flat.
    #[arg(long, value_delimiter = ',', default_value = "bias,dark,flat")]
    pub stacks: Vec<String>,
    /// Seed of the frames (the sensor's own maps have a fixed seed per preset).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// `--rts SHARE,JUMP`.
fn parse_rts(text: &str) -> std::result::Result<(f32, f32), String> {
    let parse = |v: &str| v.trim().parse::<f32>().map_err(|e| format!("{v:?}: {e}"));
    match text.split_once(',') {
        Some((f, a)) => Ok((parse(f)?, parse(a)?)),
        None => Err(format!("{text:?}: expected SHARE,JUMP (e.g. 0.002,40)")),
    }
}

impl SimulateArgs {
    /// The library's config of these flags.
    fn config(&self) -> StacksConfig {
        StacksConfig {
            preset: self.preset.clone(),
            frames: self.frames,
            dark_frames: self.dark_frames,
            output: self.output.clone(),
            width: self.width,
            height: self.height,
            dark_law: self.dark_law,
            dark_offset: self.dark_offset,
            dark_exposures: self.dark_exposures.clone(),
            lamp_drift: self.lamp_drift,
            frame_offset: self.frame_offset,
            temperature: self.temperature,
            mono: self.mono,
            vignetting: self.vignetting,
            dark_doubling: self.dark_doubling,
            read_tails: self.read_tails,
            rts: self.rts,
            format: if self.fits {
                FrameFormat::Fits
            } else {
                FrameFormat::Dng
            },
            stacks: self.stacks.clone(),
            seed: self.seed,
        }
    }
}

pub fn run(a: &SimulateArgs) -> Result<()> {
    let bar = Bar::new("simulating", 0, "frames", false);
    let written = write_stacks(&a.config(), &bar)?;
    eprintln!(
        "wrote {} frames ({}x{}, ISO {}, K {:.4} DN/e-, {} dark law) and truth.safetensors to {}",
        written.frames,
        a.width,
        a.height,
        written.spec.iso,
        written.spec.k,
        match a.dark_law {
            DarkLaw::Sqrt => "sqrt",
            DarkLaw::Linear => "linear",
        },
        a.output.display()
    );
    Ok(())
}
