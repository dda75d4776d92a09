//! How every command opens its input: a camera RAW through rawler, or a
//! headerless dump when the user gives its geometry; level overrides for both.

use anyhow::{bail, Result};
use clap::Args;
use pgrf_core::parse::ParseError;
use pgrf_raw::{decode_file, read_headerless, Cfa, HeaderlessSpec, LevelOverrides, RawFrame};
use std::path::Path;

#[derive(Args, Debug, Clone, Default)]
pub struct InputArgs {
    /// Black level override in DN: one value, or four for R,G1,B,G2 (comma separated).
    #[arg(long, value_delimiter = ',', num_args = 1..=4)]
    pub black: Option<Vec<f32>>,
    /// White (saturation) level override in DN.
    #[arg(long)]
    pub white: Option<u32>,
    /// Headerless dump: width in pixels (makes FILE a bare u16 dump).
    #[arg(long, requires_all = ["height", "cfa"], help_heading = "Headerless dumps")]
    pub width: Option<usize>,
    /// Headerless dump: height in pixels.
    #[arg(long, requires = "width", help_heading = "Headerless dumps")]
    pub height: Option<usize>,
    /// Headerless dump: CFA phase (RGGB, BGGR, GRBG, GBRG), or "mono" for a
    /// sensor without a colour filter.
    #[arg(long, requires = "width", value_parser = parse_layout, help_heading = "Headerless dumps")]
    pub cfa: Option<Layout>,
    /// Headerless dump: significant bits per sample.
    #[arg(long, default_value_t = 14, help_heading = "Headerless dumps")]
    pub bits: u32,
    /// Headerless dump: samples are big-endian (default little-endian).
    #[arg(long, help_heading = "Headerless dumps")]
    pub big_endian: bool,
}

/// What `--cfa` names: a Bayer phase, or no colour filter.
#[derive(Clone, Copy, Debug)]
pub struct Layout(pub Option<Cfa>);

/// `--cfa`: "mono", or a Bayer phase ([`Cfa`]'s words when it is neither).
fn parse_layout(s: &str) -> std::result::Result<Layout, ParseError> {
    if s.eq_ignore_ascii_case("mono") {
        return Ok(Layout(None));
    }
    s.parse::<Cfa>().map(|c| Layout(Some(c)))
}

impl InputArgs {
    pub fn overrides(&self) -> LevelOverrides {
        LevelOverrides {
            black: self.black.clone(),
            white: self.white,
        }
    }

    /// Open `path` as this command was told to.
    pub fn open(&self, path: &Path) -> Result<RawFrame> {
        match (self.width, self.height, self.cfa) {
            (Some(width), Some(height), Some(Layout(cfa))) => {
                let Some(black) = self.black.clone() else {
                    bail!("a headerless dump needs --black (its black level in DN)");
                };
                let spec = HeaderlessSpec {
                    width,
                    height,
                    bits: self.bits,
                    cfa,
                    black,
                    white: self.white,
                    big_endian: self.big_endian,
                };
                let frame = read_headerless(path, &spec)?;
                let above = pgrf_raw::headerless::samples_above_range(&frame);
                if above > 0 {
                    eprintln!(
                        "pgrf: warning: {}: {above} samples exceed the {}-bit range (defective pixels?); kept as they are",
                        path.display(),
                        self.bits
                    );
                }
                Ok(frame)
            }
            _ => Ok(decode_file(path, &self.overrides())?),
        }
    }
}
