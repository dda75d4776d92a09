//! `pgrf chart`: render the built-in colour test chart as a DNG.

use anyhow::{bail, Result};
use clap::Args;
use pgrf_raw::{write_dng, Cfa, DngOptions};
use pgrf_scenes::chart::{chart_display_gain, render_chart, ChartSpec};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ChartArgs {
    /// Output DNG.
    #[arg(short, long)]
    pub output: PathBuf,
    #[arg(long, default_value_t = 1200)]
    pub width: usize,
    #[arg(long, default_value_t = 800)]
    pub height: usize,
    /// CFA phase of the rendered mosaic.
    #[arg(long, default_value = "RGGB")]
    pub cfa: Cfa,
    /// Black level in DN.
    #[arg(long, default_value_t = 512.0)]
    pub black: f32,
    /// White level in DN.
    #[arg(long, default_value_t = 16383)]
    pub white: u32,
    /// Fraction of the black..white range a white reflector reaches.
    #[arg(long, default_value_t = 0.5)]
    pub exposure: f32,
}

pub fn run(a: &ChartArgs) -> Result<()> {
    if a.width < 60 || a.height < 40 || a.width > 20000 || a.height > 20000 {
        bail!(
            "chart size {}x{} is outside 60x40 ..= 20000x20000",
            a.width,
            a.height
        );
    }
    if !(a.exposure > 0.0 && a.exposure <= 1.0) {
        bail!("--exposure must be in (0, 1], got {}", a.exposure);
    }
    let spec = ChartSpec {
        width: a.width,
        height: a.height,
        cfa: a.cfa,
        black: a.black,
        white: a.white,
        exposure: a.exposure,
        ..Default::default()
    };
    let frame = render_chart(&spec)?;
    write_dng(&frame, &a.output, &DngOptions::default())?;
    eprintln!(
        "wrote {} ({} x {} {}); `pgrf preview --gain {:.3}` shows it at reference brightness",
        a.output.display(),
        a.width,
        a.height,
        a.cfa,
        chart_display_gain(&spec)
    );
    Ok(())
}
