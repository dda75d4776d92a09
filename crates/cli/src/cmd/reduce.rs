//! `pgrf reduce`: light frames calibrated with the masters and the
//! calibration file of `pgrf calibrate --masters DIR -o FILE`. The recipe is
//! `pgrf_calib::reduce`; this turns the flags into its config.

use crate::progress::Bar;
use anyhow::Result;
use clap::Args;
use pgrf_calib::reduce::{reduce_to_files, ReduceConfig};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ReduceArgs {
    /// Light frames (FITS or camera RAW), or folders of them, of the calibrated camera, size, filter layout and ISO.
    #[arg(required = true)]
    pub lights: Vec<PathBuf>,
    /// The masters folder `pgrf calibrate --masters DIR` wrote: master_bias, master_dark_EXPOSUREs (e.g. master_dark_10s; the one nearest each light's exposure is scaled to it), master_flat_EXPOSUREs (the brightest is used).
    #[arg(long)]
    pub masters: PathBuf,
    /// The calibration file of the same run (`pgrf calibrate -o`): its dark law scales the darks, its defect map drives the cosmetic correction.
    #[arg(long)]
    pub calib: PathBuf,
    /// Output folder (created if missing): one file per light, its file name kept with only the final extension changed (M51.00000003.FIT -> M51.00000003.fits), FITS (32-bit float, 0-1) for FITS lights, DNG for camera RAWs.
    #[arg(short, long)]
    pub output: PathBuf,
    /// How far (°C) a light's recorded temperature may lie from the calibration's [default: 2].
    #[arg(long)]
    pub temperature_tolerance: Option<f32>,
    /// Also print what was done as one JSON line on stdout (each light's input, output, exposure, master dark and scale, defects replaced; the masters and dark law).
    #[arg(long)]
    pub json: bool,
}

impl ReduceArgs {
    /// The library's config of these flags (it checks them).
    fn config(&self) -> ReduceConfig {
        ReduceConfig {
            lights: self.lights.clone(),
            masters: self.masters.clone(),
            calib: self.calib.clone(),
            output: self.output.clone(),
            temperature_tolerance: self.temperature_tolerance,
        }
    }
}

pub fn run(a: &ReduceArgs) -> Result<()> {
    let config = a.config();
    let bar = Bar::new("reducing", 0, "lights", false);
    let outcome = reduce_to_files(&config, &bar)?;
    for l in &outcome.lights {
        let dark = match &l.dark {
            Some(d) => match d.temperature_scale {
                Some(f) => format!(
                    ", {} x{:.4}, x{f:.4} to the light's temperature",
                    d.master, d.scale
                ),
                None => format!(", {} x{:.4}", d.master, d.scale),
            },
            None => String::new(),
        };
        let c = &l.cosmetic;
        let edge = match (c.along_row, c.kept) {
            (0, 0) => String::new(),
            (n, 0) => format!(", {n} of them from the nearest good pixels along the row"),
            (n, k) => format!(", {n} of them along the row; {k} kept: no good pixel in their row"),
        };
        eprintln!(
            "{} -> {} ({} defects replaced{edge}{dark})",
            l.input.display(),
            l.output.display(),
            c.replaced
        );
    }
    eprintln!(
        "reduced {} lights with {}, {} and the {} dark law",
        outcome.lights.len(),
        outcome.bias,
        outcome.flat,
        outcome.law
    );
    if a.json {
        println!("{}", serde_json::to_string(&outcome)?);
    }
    Ok(())
}
