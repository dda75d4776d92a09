//! `pgrf synth`: a clean RAW in, a simulated low-light capture of the same
//! scene out (as a DNG, or a FITS file when `-o` names one, with the
//! input's size, CFA or monochrome layout, and levels): by default
//! the dark capture the camera would record (un-amplified, EXIF exposure
//! divided by the ratio), so that `pgrf enhance --ratio R` restores it;
//! `--brightened` writes it multiplied back by the ratio instead. The
//! recipe is `pgrf_calib::synth::synthesize`; this reads the frame, writes
//! the result (and preview) and prints.

use crate::input::InputArgs;
use anyhow::{bail, Result};
use clap::Args;
use pgrf_calib::synth::{synthesize, SynthConfig};
use pgrf_noise::{DarkLaw, ModelKind};
use pgrf_raw::{
    render_preview, write_dng, write_fits_frame, DngOptions, FrameFormat, PreviewOptions,
};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct SynthArgs {
    /// Clean (long-exposure) RAW file or headerless dump.
    pub clean: PathBuf,
    /// Camera profile: a built-in name (sony-a7s2, nikon-d850, canon-eos70d,
    /// canon-eos700d, canon-eos5d4), darktable:"MAKER MODEL", dng:FILE.dng or a JSON file.
    #[arg(long)]
    pub profile: String,
    /// Exposure ratio, 1 to 10000 (the capture is this many times darker). Default: drawn from U(100, 300) by the seed.
    #[arg(long)]
    pub ratio: Option<f32>,
    /// ISO of the simulated capture. Default: the file's ISO; if it has none,
    /// parameters are drawn from the profile's ELD distribution.
    #[arg(long)]
    pub iso: Option<u32>,
    /// Noise model: pg (Poisson-Gaussian), eld, pgrf (`--model`, its old name, still works).
    #[arg(long, alias = "model", default_value = "pgrf")]
    pub noise_model: ModelKind,
    /// PGRF components: any of P (photon shot), G (read), H (row), Q (quantisation), F (fixed pattern), A (dark current).
    #[arg(long, default_value = "P,G,H,Q,F,A")]
    pub components: String,
    /// The "noD" ablation: global instead of per-pixel calibration.
    #[arg(long)]
    pub global: bool,
    /// ELD model with Gaussian instead of Tukey-lambda read noise.
    #[arg(long)]
    pub gaussian_read: bool,
    /// Exposure time of the simulated capture in seconds (drives dark current).
    /// Default: the file's exposure divided by the ratio, else drawn from 1/30..1 s.
    #[arg(long)]
    pub exposure_time: Option<f32>,
    /// Dark-current rate in electrons per sqrt(s) (sqrt law) or per s (linear
    /// law), replacing the profile's (the built-in profiles have no measured one).
    #[arg(long)]
    pub dark_rate: Option<f64>,
    /// Time law of the dark signal: sqrt (the paper's fit) or linear.
    #[arg(long, default_value = "sqrt")]
    pub dark_law: DarkLaw,
    /// Per-pixel calibration file (from `pgrf calibrate`) for the PGRF model:
    /// its maps, gain and row noise replace the profile's.
    #[arg(long)]
    pub calib: Option<PathBuf>,
    /// Apply a calibration of another camera or ISO anyway.
    #[arg(long)]
    pub force: bool,
    /// Random seed: same arguments and seed give byte-identical output.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output frame: a FITS file when the name ends .fits, .fit or .fts
    /// (16-bit, the input's row order, exposure and header kept, as an
    /// astronomy camera's frames are), else a DNG.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Also write an sRGB preview of the result.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Exposure gain for the PNG preview [default: the ratio for the dark
    /// capture, so the preview shows the scene at the clean frame's
    /// brightness; 1 with --brightened].
    #[arg(long)]
    pub png_gain: Option<f32>,
    /// Write the capture brightened: multiplied back by the ratio and
    /// clipped to black..white, as a network is fed it (what `pgrf synth`
    /// wrote before). Without it the output is the dark capture the camera
    /// would record, for `pgrf enhance --ratio R`.
    #[arg(long)]
    pub brightened: bool,
    /// Also simulate this many masked (optical-black) columns left of the
    /// frame, written as the DNG's MaskedAreas: dark pixels with the
    /// capture's offset and noise, as a camera's readout has them, from
    /// which `pgrf enhance` measures the black level (even; DNG output
    /// only; not with --calib).
    #[arg(long, default_value_t = 0)]
    pub masked_columns: usize,
    /// Draw the read, row and quantisation noise from --calib's noise bank (the residuals of the bias frames it was made from: their tails, random telegraph pixels and row and column structure) instead of the parametric model.
    #[arg(long)]
    pub noise_bank: bool,
    #[command(flatten)]
    pub input: InputArgs,
}

pub fn run(a: &SynthArgs, g: &crate::Globals) -> Result<()> {
    if let Some(g) = a.png_gain {
        if !(g.is_finite() && g > 0.0) {
            bail!("--png-gain must be a positive number, got {g}");
        }
    }
    pgrf_calib::synth::check(&config(a, g))?;
    if a.masked_columns > 0 && FrameFormat::of_path(&a.output).ok() == Some(FrameFormat::Fits) {
        bail!("--masked-columns writes the DNG's MaskedAreas; a FITS output has no masked area (name the output .dng)");
    }
    let frame = a.input.open(&a.clean)?;
    let made = synthesize(&frame, &a.clean, &config(a, g))?;
    // A FITS name gets FITS (an astronomy camera's frame stays one); any
    // other name the DNG synth has always written.
    match FrameFormat::of_path(&a.output) {
        Ok(FrameFormat::Fits) => write_fits_frame(&made.frame, &a.output)?,
        _ => write_dng(&made.frame, &a.output, &DngOptions::default())?,
    }
    eprintln!(
        "wrote {} {}",
        a.output.display(),
        made.summary(&config(a, g))
    );
    if let Some(png) = &a.png {
        let prev = render_preview(
            &made.frame,
            &PreviewOptions {
                gain: a
                    .png_gain
                    .unwrap_or(if a.brightened { 1.0 } else { made.info.ratio }),
                ..Default::default()
            },
        )?;
        prev.write_png(png, 8)?;
        eprintln!("wrote {}", png.display());
    }
    Ok(())
}

/// The flags as the recipe's settings.
fn config(a: &SynthArgs, g: &crate::Globals) -> SynthConfig {
    SynthConfig {
        profile: a.profile.clone(),
        ratio: a.ratio,
        iso: a.iso,
        model: a.noise_model,
        components: a.components.clone(),
        global: a.global,
        gaussian_read: a.gaussian_read,
        exposure_time: a.exposure_time,
        dark_rate: a.dark_rate,
        dark_law: a.dark_law,
        calib: a.calib.clone(),
        force: a.force,
        seed: a.seed,
        brightened: a.brightened,
        masked_columns: a.masked_columns,
        noise_bank: a.noise_bank,
        darktable: g.darktable.map(Into::into),
    }
}
