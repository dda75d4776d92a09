//! `pgrf calibrate`'s flags (the `clap` feature) and the run they ask for:
//! the flags and their checks live beside the recipe they drive, so a new
//! option is added in one crate.

use crate::outputs::{CalibrateConfig, DarktableOutput, ReportOutput};
use crate::{CalibError, CalibrateInput, Result};
use pgrf_core::paths::require_tree_root;
use pgrf_raw::files::list_files;
use std::path::{Path, PathBuf};

/// `pgrf calibrate`'s flags.
#[derive(clap::Args, Debug)]
pub struct CalibrateArgs {
    /// Folder of bias frames (shortest exposure, lens capped).
    #[arg(long)]
    pub bias: PathBuf,
    /// Folder of dark frames (lens capped, two or more exposure times, read from each file: a camera RAW's EXIF ExposureTime, a FITS file's EXPTIME or EXPOSURE; any number of frames at each, one is fine).
    #[arg(long)]
    pub dark: Option<PathBuf>,
    /// Folder of dark frames taken at other sensor temperatures than the rest (CCD-TEMP in FITS; any exposures, grouped by temperature): with --dark, they measure the temperature rise that doubles the dark current, which `pgrf reduce` scales a light's dark by.
    #[arg(long)]
    pub temperature_darks: Option<PathBuf>,
    /// Folder of flat-field frames (uniform light; two or more levels, told apart by exposure time: EXIF ExposureTime, or FITS EXPTIME or EXPOSURE).
    #[arg(long)]
    pub flat: PathBuf,
    /// ISO the frames must have (used when the files carry none). A camera RAW records it in EXIF; a FITS file only as ISOSPEED (a DSLR's, saved by a capture program); an astronomy camera's FITS has none (its GAIN keyword is a driver setting, not an ISO) and is calibrated without it: only the darktable entry, which darktable files by ISO, is then left out unless --iso names one.
    #[arg(long)]
    pub iso: Option<u32>,
    /// Output calibration file (safetensors maps + JSON record).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Folder for the report (PNG plots and summary.md); created if missing, with its parent folders.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// End with one JSON line of the global results.
    #[arg(long)]
    pub json: bool,
    /// Drop frames whose mean or noise stands out from their stack (robust z-score above 5) instead of only naming them.
    #[arg(long)]
    pub reject: bool,
    /// How far (°C) a frame's recorded temperature may lie from the frames' median [default: 2].
    #[arg(long)]
    pub temperature_tolerance: Option<f32>,
    /// Folder for master frames (created if missing, with its parent folders): master_bias, one master_dark_EXPOSUREs per dark exposure (master_dark_10s), one master_flat_EXPOSUREs per flat level (each stack's mean, in the camera's mosaic and levels: DNG, or FITS when the frames are FITS) and defects.png.
    #[arg(long)]
    pub masters: Option<PathBuf>,
    /// Add the calibrated camera's darktable noise-profile entry (at its ISO) to this darktable noiseprofiles.json, created if missing: a copy of darktable's own file, or one that earlier calibrations at other ISOs wrote; an entry of the same camera at the same ISO is replaced. Without it the entry is written alone beside -o as OUTPUT.noiseprofiles.json. darktable reads such a file with `darktable --noiseprofiles FILE`.
    #[arg(long)]
    pub darktable_into: Option<PathBuf>,
    /// The maker name the darktable entry is filed under [default: the frames' maker as pgrf reads it, rawspeed's clean name for native RAWs]. darktable uses the entry for images whose maker contains this string.
    #[arg(long)]
    pub darktable_maker: Option<String>,
    /// The model name the darktable entry is filed under [default: the frames' model as pgrf reads it]. darktable uses the entry only for images whose model, as darktable names it, is exactly this: set it where the names differ (an alias: the EOS Kiss X4 is the EOS 550D, the name darktable's own file uses).
    #[arg(long)]
    pub darktable_model: Option<String>,
}

/// An output folder option: an existing file is refused, and so is a path
/// under a file (the folder and any missing parents are created by the
/// run).
fn check_folder(flag: &'static str, dir: &Path, refusal: &str) -> Result<()> {
    if dir.exists() && !dir.is_dir() {
        return Err(CalibError::BadOption {
            flag,
            message: format!("{flag} {} is a file; give a folder{refusal}", dir.display()),
        });
    }
    require_tree_root(dir).map_err(|e| CalibError::BadOption {
        flag,
        message: format!("{flag}: {e}"),
    })
}

impl CalibrateArgs {
    /// The run the flags ask for, its options checked before any work: the
    /// frame folders listed, the report and masters folders, the
    /// temperature tolerance, the darktable names. `report_files` are the
    /// names the caller's report will write.
    pub fn config(&self, report_files: &[&'static str]) -> Result<CalibrateConfig> {
        let bias = list_files(&self.bias)?;
        let flat = list_files(&self.flat)?;
        let dark = match &self.dark {
            Some(d) => list_files(d)?,
            None => Vec::new(),
        };
        let temperature_darks = match &self.temperature_darks {
            Some(d) => list_files(d)?,
            None => Vec::new(),
        };
        if let Some(dir) = &self.report {
            check_folder("--report", dir, " for the report")?;
        }
        crate::calibrate::check_temperature_tolerance(self.temperature_tolerance)?;
        if let Some(dir) = &self.masters {
            check_folder("--masters", dir, "")?;
        }
        for (flag, name) in [
            ("--darktable-maker", &self.darktable_maker),
            ("--darktable-model", &self.darktable_model),
        ] {
            if name.as_deref().is_some_and(|n| n.trim().is_empty()) {
                return Err(CalibError::BadOption {
                    flag,
                    message: format!(
                        "{flag} is empty: darktable finds an entry by maker and model"
                    ),
                });
            }
        }
        Ok(CalibrateConfig {
            input: CalibrateInput {
                bias,
                dark,
                flat,
                iso: self.iso,
                tap_pixels: 4096,
                reject: self.reject,
                masters: self.masters.is_some(),
                temperature_tolerance: self.temperature_tolerance,
                temperature_darks,
            },
            output: self.output.clone(),
            masters: self.masters.clone(),
            report: self.report.clone().map(|dir| ReportOutput {
                dir,
                files: report_files.to_vec(),
            }),
            darktable: DarktableOutput {
                into: self.darktable_into.clone(),
                maker: self.darktable_maker.clone(),
                model: self.darktable_model.clone(),
            },
        })
    }
}
