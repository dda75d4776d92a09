//! `pgrf convert`: any RAW pgrf reads -> DNG, pixels and metadata kept.

use crate::input::InputArgs;
use anyhow::Result;
use clap::Args;
use pgrf_raw::{write_dng, Compression, DngOptions};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ConvertArgs {
    /// RAW file or headerless dump.
    pub file: PathBuf,
    /// Output DNG (written atomically).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Store pixels uncompressed instead of LJPEG-92 lossless.
    #[arg(long)]
    pub uncompressed: bool,
    #[command(flatten)]
    pub input: InputArgs,
}

pub fn run(a: &ConvertArgs) -> Result<()> {
    crate::output::check_outputs(&[("-o", &a.output)], &[&a.file])?;
    let frame = a.input.open(&a.file)?;
    let opts = DngOptions {
        compression: if a.uncompressed {
            Compression::Uncompressed
        } else {
            Compression::Lossless
        },
        ..Default::default()
    };
    write_dng(&frame, &a.output, &opts)?;
    eprintln!(
        "wrote {} ({} x {} {}, black {:?}, white {})",
        a.output.display(),
        frame.width,
        frame.height,
        frame.cfa,
        frame.black,
        frame.white
    );
    Ok(())
}
