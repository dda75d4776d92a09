//! `pgrf convert`: any RAW pgrf reads (camera RAW, FITS, headerless dump)
//! -> DNG, or -> FITS when the output is named .fits/.fit/.fts, pixels and
//! metadata kept.

use crate::input::InputArgs;
use anyhow::Result;
use clap::Args;
use pgrf_raw::{write_frame, Compression, DngOptions, FrameFormat};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ConvertArgs {
    /// RAW file, FITS file or headerless dump.
    pub file: PathBuf,
    /// Output DNG, or FITS (16-bit) when named .fits, .fit or .fts (written atomically).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Store pixels uncompressed instead of LJPEG-92 lossless.
    #[arg(long)]
    pub uncompressed: bool,
    #[command(flatten)]
    pub input: InputArgs,
}

pub fn run(a: &ConvertArgs) -> Result<()> {
    let frame = a.input.open(&a.file)?;
    let (w, h) = (frame.width, frame.height);
    pgrf_raw::memory::check_frame(&a.file, "writing", w, h, pgrf_raw::memory::WRITE)?;
    let opts = DngOptions {
        compression: if a.uncompressed {
            Compression::Uncompressed
        } else {
            Compression::Lossless
        },
        ..Default::default()
    };
    let format = write_frame(&frame, &a.output, &opts)?;
    if format == FrameFormat::Fits && frame.black.iter().any(|&b| b != 0.0) {
        eprintln!(
            "pgrf: warning: FITS has no black-level keyword: the black level {:?} is not in {}; give --black when reading it",
            frame.black,
            a.output.display()
        );
    }
    eprintln!(
        "wrote {} ({} x {} {}, black {:?}, white {})",
        a.output.display(),
        frame.width,
        frame.height,
        frame.layout(),
        frame.black,
        frame.white
    );
    Ok(())
}
