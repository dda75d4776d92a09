//! A calibration run written out: the master frames, the darktable
//! noise-profile entry and the calibration file, each checked before any
//! is written ([`calibrate_to_files`], what `pgrf calibrate` runs).
//!
//! The report's plots are drawn by pgrf-report, which sits beside this crate
//! (neither depends on the other), so the caller draws them, at the point of
//! the run this module gives it ([`RunHooks::write_report`]). Outputs are
//! checked before any frame is read ([`pgrf_core::paths::check_outputs`]:
//! inputs not overwritten, no output named twice).

use crate::calibrate::{calibrate, CalibrateInput, CalibrationRun};
use crate::error::{CalibError, Result};
use crate::masters::defect_picture;
use pgrf_core::paths::check_outputs;
use pgrf_core::Progress;
use pgrf_noise::darktable::{Export, NoiseProfiles, VARIANCE_FACTOR};
use std::path::{Path, PathBuf};

/// A calibration run and everything it writes.
#[derive(Clone, Debug, Default)]
pub struct CalibrateConfig {
    /// The frames and how to read them ([`CalibrateInput::masters`] is set
    /// from `masters`).
    pub input: CalibrateInput,
    /// The calibration file (safetensors maps + JSON record), written last.
    pub output: PathBuf,
    /// Folder for the master frames and defects.png, created if missing.
    pub masters: Option<PathBuf>,
    /// Folder for the report, created if missing; the caller draws it.
    pub report: Option<ReportOutput>,
    /// Where the darktable noise-profile entry goes and what it is filed under.
    pub darktable: DarktableOutput,
}

/// The report's folder and the names of the files the caller will write
/// there (checked with the other outputs before the run).
#[derive(Clone, Debug, Default)]
pub struct ReportOutput {
    /// The folder.
    pub dir: PathBuf,
    /// The names of its files.
    pub files: Vec<&'static str>,
}

/// The darktable entry: the file it is merged into and its maker and model.
#[derive(Clone, Debug, Default)]
pub struct DarktableOutput {
    /// A darktable noiseprofiles.json to add the entry to (created if
    /// missing); None: the entry is written alone beside the calibration
    /// file, as OUTPUT.noiseprofiles.json.
    pub into: Option<PathBuf>,
    /// The maker the entry is filed under [default: the frames'].
    pub maker: Option<String>,
    /// The model the entry is filed under [default: the frames'].
    pub model: Option<String>,
}

/// What the caller does at its points of the run.
pub trait RunHooks {
    /// The caller's error; the run's own errors convert into it.
    type Error: From<CalibError>;
    /// Draw the report into `dir` (it exists); called after the master
    /// frames and before the darktable entry and the calibration file.
    /// Returns how many files it wrote.
    fn write_report(
        &self,
        dir: &Path,
        run: &CalibrationRun,
    ) -> std::result::Result<usize, Self::Error>;
}

/// What [`calibrate_to_files`] wrote, for the caller to tell.
pub struct CalibrateOutcome {
    /// The run: the calibration (saved at [`CalibrateConfig::output`]) and
    /// its estimates.
    pub run: CalibrationRun,
    /// Master frames written (defects.png besides), with `masters`.
    pub masters: Option<usize>,
    /// Report files the caller wrote, with `report`.
    pub report: Option<usize>,
    /// What became of the darktable entry.
    pub darktable: DarktableOutcome,
}

/// What became of the darktable entry.
pub enum DarktableOutcome {
    /// Written into `path`.
    Written {
        /// The darktable file.
        path: PathBuf,
        /// Entries of the same camera at the same ISO it replaced.
        replaced: usize,
        /// The entry's name ("MAKER MODEL iso ISO").
        name: String,
    },
    /// Not written: the frames `lack` what darktable finds an entry by
    /// ("record no ISO (give --iso)", ...), and no file was asked for.
    Skipped {
        /// What the frames lack, and the option that gives it.
        lack: &'static str,
    },
}

/// The darktable file a calibration written to `output` updates, and the
/// option that named it, for messages: `into` (`--darktable-into`), else
/// beside the calibration file.
pub fn darktable_file(into: Option<&Path>, output: &Path) -> (&'static str, PathBuf) {
    match into {
        Some(p) => ("--darktable-into", p.to_path_buf()),
        None => (
            "-o (its darktable entry)",
            output.with_extension("noiseprofiles.json"),
        ),
    }
}

impl CalibrateConfig {
    /// [`darktable_file`] of this run.
    pub fn darktable_file(&self) -> (&'static str, PathBuf) {
        darktable_file(self.darktable.into.as_deref(), &self.output)
    }
}

/// Calibrate ([`calibrate()`]) and write what `config` asks for: the master
/// frames, the report (through `hooks`), the darktable entry and, last, the
/// calibration file, which appears only when everything else has been
/// written. The darktable file to merge into is read, and every output
/// checked, before any frame is; the darktable entry is made (and refused)
/// before anything is written. Reports frames read to `progress`, and
/// finishes it when the frames are read.
pub fn calibrate_to_files<H: RunHooks>(
    config: &CalibrateConfig,
    progress: &dyn Progress,
    hooks: &H,
) -> std::result::Result<CalibrateOutcome, H::Error> {
    let input = &config.input;
    let inputs: Vec<&Path> = input
        .bias
        .iter()
        .chain(&input.flat)
        .chain(&input.dark)
        .map(|p| p.as_path())
        .collect();
    let (flag, darktable_file) = config.darktable_file();
    let existing = read_darktable(config)?;
    // A report folder that does not exist yet holds no input and no folder
    // in a report file's way; it is made after the calibration.
    let report_files: Vec<PathBuf> = match &config.report {
        Some(r) if r.dir.is_dir() => r.files.iter().map(|f| r.dir.join(f)).collect(),
        _ => Vec::new(),
    };
    let mut outputs = vec![("-o", config.output.as_path()), (flag, &darktable_file)];
    outputs.extend(report_files.iter().map(|p| ("--report", p.as_path())));
    check_outputs(&outputs, &inputs).map_err(CalibError::from)?;
    let input = CalibrateInput {
        masters: config.masters.is_some(),
        ..input.clone()
    };
    let run = calibrate(&input, progress)?;
    progress.finish();
    let entry = darktable_entry(config, &run, existing.as_deref())?;
    let masters = match &config.masters {
        Some(dir) => Some(write_masters(dir, &run, &inputs, &config.output)?),
        None => None,
    };
    let report = match &config.report {
        Some(r) => {
            create_folder(&r.dir, "report folder")?;
            Some(hooks.write_report(&r.dir, &run)?)
        }
        None => None,
    };
    let darktable = match entry {
        Entry::Made {
            text,
            replaced,
            name,
        } => {
            pgrf_core::write_atomic(&darktable_file, text.as_bytes()).map_err(|source| {
                CalibError::DarktableWrite {
                    path: darktable_file.clone(),
                    source,
                }
            })?;
            DarktableOutcome::Written {
                path: darktable_file,
                replaced,
                name,
            }
        }
        Entry::Lacking(lack) => DarktableOutcome::Skipped { lack },
    };
    run.calibration.save(&config.output)?;
    Ok(CalibrateOutcome {
        run,
        masters,
        report,
        darktable,
    })
}

/// The text of the darktable file to merge into, read before any work so
/// that a malformed one stops the run at once; None when there is none yet.
fn read_darktable(config: &CalibrateConfig) -> Result<Option<String>> {
    match &config.darktable.into {
        Some(p) if p.exists() => {
            let text = std::fs::read_to_string(p).map_err(|source| CalibError::DarktableRead {
                path: p.clone(),
                source,
            })?;
            NoiseProfiles::parse(&text, p)
                .map_err(|source| CalibError::DarktableParse { source })?;
            Ok(Some(text))
        }
        _ => Ok(None),
    }
}

fn create_folder(dir: &Path, what: &'static str) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|source| CalibError::CreateFolder {
        path: dir.to_path_buf(),
        what,
        source,
    })
}

/// The master frames and the defect picture into `dir` (created if
/// missing), each checked against the inputs and `output` before any is
/// written; returns how many masters were written.
fn write_masters(
    dir: &Path,
    run: &CalibrationRun,
    inputs: &[&Path],
    output: &Path,
) -> Result<usize> {
    let ext = if run.key.fits { "fits" } else { "dng" };
    let files: Vec<PathBuf> = run
        .masters
        .iter()
        .map(|m| dir.join(format!("{}.{ext}", m.name)))
        .chain(std::iter::once(dir.join("defects.png")))
        .collect();
    if dir.is_dir() {
        let mut outputs = vec![("-o", output)];
        outputs.extend(files.iter().map(|f| ("--masters", f.as_path())));
        check_outputs(&outputs, inputs)?;
    }
    create_folder(dir, "the masters folder")?;
    let meta = &run.calibration.meta;
    for (m, path) in run.masters.iter().zip(&files) {
        let written: std::result::Result<(), Box<dyn std::error::Error + Send + Sync>> =
            if run.key.fits {
                m.fits(&run.key, meta.k, meta.temperature_c)
                    .map_err(Into::into)
                    .and_then(|bytes| Ok(pgrf_core::write_atomic(path, &bytes)?))
            } else {
                pgrf_raw::write_dng(&m.frame(&run.key)?, path, &Default::default())
                    .map_err(Into::into)
            };
        written.map_err(|source| CalibError::WriteMaster {
            path: path.clone(),
            source,
        })?;
    }
    let key = &run.key;
    let picture = pgrf_raw::Preview {
        width: key.width,
        height: key.height,
        rgb: defect_picture(&run.calibration.maps.defects, key),
        warnings: Vec::new(),
    };
    picture
        .write_png(files.last().expect("defects.png"), 8)
        .map_err(CalibError::DefectPicture)?;
    Ok(run.masters.len())
}

/// The darktable entry of a run, before it is written.
enum Entry {
    /// The darktable file's text with the entry, how many entries it
    /// replaced, and the entry's name.
    Made {
        text: String,
        replaced: usize,
        name: String,
    },
    /// What the frames lack for an entry.
    Lacking(&'static str),
}

/// The calibrated camera's darktable entry ([`Export`]) merged into
/// `existing`; or what the frames lack for one when they carry no ISO,
/// maker or model and no file was asked for (asked for, that is an error).
fn darktable_entry(
    config: &CalibrateConfig,
    run: &CalibrationRun,
    existing: Option<&str>,
) -> Result<Entry> {
    let m = &run.calibration.meta;
    let d = &config.darktable;
    let maker = d.maker.clone().unwrap_or_else(|| m.make.clone());
    let model = d.model.clone().unwrap_or_else(|| m.model.clone());
    let (flag, path) = config.darktable_file();
    // darktable finds an entry by maker, model and ISO; frames without them
    // (FITS from an astronomy camera names no maker) get no entry unless
    // one was asked for.
    let missing = if m.iso.is_none() {
        Some("record no ISO (give --iso)")
    } else if maker.trim().is_empty() || model.trim().is_empty() {
        Some("name no camera maker or model (give --darktable-maker and --darktable-model)")
    } else {
        None
    };
    if let Some(what) = missing {
        if d.into.is_some() {
            return Err(CalibError::DarktableUnnamed { path, what });
        }
        return Ok(Entry::Lacking(what));
    }
    let iso = m.iso.expect("checked above");
    let [s, o] = run.noise_profile();
    let export = Export {
        maker,
        model,
        iso,
        s,
        o,
        comment: format!(
            "measured by pgrf calibrate: K {:.4} DN/e-, photosite variance S x + O on [0, 1] with S {s:.6e}, O {o:.6e}; a, b = S, O / {} (darktable's PPG profiling chain)",
            m.k,
            VARIANCE_FACTOR
        ),
    };
    let (text, replaced) =
        export
            .merge_into(existing, &path)
            .map_err(|source| CalibError::DarktableMerge {
                flag,
                path: path.clone(),
                source,
            })?;
    Ok(Entry::Made {
        text,
        replaced,
        name: export.entry_name(),
    })
}
