//! A whole evaluation as `pgrf eval` runs it: a protocol's cases found from
//! an [`EvalConfig`], every method under test run on them and measured, the
//! table with the header that says how ([`run_protocol`]), then the per-image
//! CSV, the Markdown table and the worst-images picture
//! ([`Evaluation::write`]).
//!
//! - `header`: the lines that state what was measured and how.
//! - `write`: the files an evaluation leaves.

mod header;
mod write;
pub use write::worst_path;

use crate::dataset::run::{Outcome, RunOptions, Worst, NOISY};
use crate::dataset::synthetic::{self, Synthetic, DEFAULT_ISOS, DEFAULT_RATIOS};
use crate::dataset::table::{summarise, Row, Summary};
use crate::dataset::{eld, pairs, sid, DatasetError, DatasetKind, Sample};
use crate::method::{MethodUnderTest, SavedOutputs};
use pgrf_core::Progress;
use pgrf_noise::ModelKind;
use pgrf_raw::LevelOverrides;
use std::path::{Path, PathBuf};

/// An error from outside this crate (loading the methods), kept whole.
pub type BoxError = Box<dyn std::error::Error + Send + Sync>;

/// Why an evaluation stopped.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// A dataset that cannot be walked, a case that cannot be loaded or
    /// measured, or a method that failed on a case (the message names it).
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// The methods could not be loaded (the caller's error, unchanged).
    #[error(transparent)]
    Methods(BoxError),
    /// A flag's value that no input can make right (named by `flag`).
    #[error("{message}")]
    BadOption {
        /// The flag, e.g. "--crop".
        flag: &'static str,
        /// What was wrong, on one line.
        message: String,
    },
    /// An `--outputs` column whose name another column already has.
    #[error("--outputs {0}=...: the name is taken by another column")]
    ColumnTaken(String),
    /// The CSV or Markdown file could not be written.
    #[error("{}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// Why not.
        #[source]
        source: pgrf_core::WriteError,
    },
    /// A preview of the worst-images picture could not be made.
    #[error(transparent)]
    Preview(#[from] pgrf_raw::RawError),
    /// The worst-images picture could not be written.
    #[error("{}: {reason}", path.display())]
    Montage {
        /// The picture.
        path: PathBuf,
        /// Why not.
        reason: pgrf_report::ReportError,
    },
}

/// The synthetic protocol's captures: ISO x ratio grid, noise and seed.
#[derive(Clone, Debug, PartialEq)]
pub struct SyntheticSpec {
    /// ISOs of the captures.
    pub isos: Vec<u32>,
    /// Exposure ratios, each >= 1.
    pub ratios: Vec<f32>,
    /// Camera noise profile (a built-in name, darktable:"MAKER MODEL",
    /// dng:FILE.dng or a JSON file).
    pub profile: String,
    /// Noise model.
    pub noise: ModelKind,
    /// The base of every capture's noise seed.
    pub seed: u64,
    /// Keep each capture's dark-level offset (an uncalibrated camera).
    pub uncalibrated: bool,
    /// Tell noise-aware methods the blind estimate, not the truth.
    pub blind_noise: bool,
    /// darktable's noiseprofiles.json for a `darktable:` profile (None:
    /// darktable's install is searched).
    pub darktable: Option<std::path::PathBuf>,
}

impl Default for SyntheticSpec {
    fn default() -> Self {
        SyntheticSpec {
            isos: DEFAULT_ISOS.to_vec(),
            ratios: DEFAULT_RATIOS.to_vec(),
            profile: "sony-a7s2".into(),
            noise: ModelKind::default(),
            seed: 0,
            uncalibrated: false,
            blind_noise: false,
            darktable: None,
        }
    }
}

/// What an evaluation measures and where it writes.
#[derive(Clone, Debug)]
pub struct EvalConfig {
    /// The benchmark.
    pub protocol: DatasetKind,
    /// Dataset folder (pairs: the CSV or its folder), exactly one for the
    /// file-pair protocols; synthetic: clean files and folders of them.
    pub roots: Vec<PathBuf>,
    /// ELD scenes, e.g. "1-10" or "1,2".
    pub scenes: String,
    /// SID list file (default ROOT/Sony_test_list.txt).
    pub list: Option<PathBuf>,
    /// SID: keep the misaligned scenes 10034, 10045, 10172.
    pub keep_misaligned: bool,
    /// The synthetic protocol's captures (read for that protocol only).
    pub synthetic: SyntheticSpec,
    /// Centre crop of the packed planes before the methods run.
    pub crop: Option<usize>,
    /// White level for normalising both files (None: each file's own).
    pub white: Option<u32>,
    /// ELD's illuminance correction for the methods.
    pub correct: bool,
    /// Add the amplified noisy input as a column.
    pub baseline: bool,
    /// Columns read from outside restorations: (name, folder of
    /// `KEY.output.npy`), after the methods.
    pub outputs: Vec<(String, PathBuf)>,
    /// Write every case's input, reference and sidecar to this folder.
    pub dump: Option<PathBuf>,
    /// Images in the worst-images picture.
    pub worst_count: usize,
    /// Per-image results as CSV.
    pub csv: Option<PathBuf>,
    /// The table in Markdown.
    pub markdown: Option<PathBuf>,
    /// The worst-images picture (None: next to `csv` as NAME_worst.png,
    /// none without it).
    pub worst: Option<PathBuf>,
}

/// What an evaluation measured.
pub struct Evaluation {
    /// What was measured and how, one statement per line (with a `note`
    /// line for each case measured differently).
    pub header: String,
    /// The table: means per row and method.
    pub summary: Summary,
    /// One row per image and method.
    pub rows: Vec<Row>,
    /// The worst images, worst first.
    pub worst: Vec<Worst>,
    /// The worst-images picture's columns: noisy input, each method,
    /// reference.
    pub worst_columns: Vec<String>,
}

/// What a run goes over: file pairs, or clean files and the synthetic recipe.
enum Cases {
    Pairs(Vec<Sample>),
    Synthetic(Vec<synthetic::Image>, Synthetic),
}

/// The file-pair protocols take exactly one root.
fn one_root(cfg: &EvalConfig) -> Result<&Path, DatasetError> {
    match cfg.roots.as_slice() {
        [r] => Ok(r),
        r => Err(DatasetError(format!(
            "--root: the {} protocol takes one folder or file, got {}",
            cfg.protocol,
            r.len()
        ))),
    }
}

/// The cases of `cfg`'s protocol, every file checked to exist.
fn find_cases(cfg: &EvalConfig) -> Result<Cases, DatasetError> {
    if cfg.protocol == DatasetKind::Synthetic {
        let s = &cfg.synthetic;
        let mut recipe = Synthetic::new(
            &s.profile,
            s.noise,
            synthetic::grid(&s.isos, &s.ratios),
            s.seed,
            s.darktable.as_deref(),
        )?;
        recipe.uncalibrated = s.uncalibrated;
        recipe.blind_noise = s.blind_noise;
        return Ok(Cases::Synthetic(synthetic::walk(&cfg.roots)?, recipe));
    }
    let root = one_root(cfg)?;
    Ok(Cases::Pairs(match cfg.protocol {
        DatasetKind::Eld => {
            let scenes = eld::parse_scenes(&cfg.scenes).map_err(|e| DatasetError(e.to_string()))?;
            eld::walk(root, &scenes)?
        }
        DatasetKind::Sid => sid::walk(root, cfg.list.as_deref(), cfg.keep_misaligned)?,
        DatasetKind::Pairs => pairs::walk(root)?,
        DatasetKind::Synthetic => unreachable!("walked above"),
    }))
}

/// The methods `load` gives, then `cfg`'s outside columns (each name must be
/// new).
fn columns(
    cfg: &EvalConfig,
    load: impl FnOnce() -> Result<Vec<Box<dyn MethodUnderTest>>, BoxError>,
) -> Result<Vec<Box<dyn MethodUnderTest>>, EvalError> {
    let mut methods = load().map_err(EvalError::Methods)?;
    for (name, dir) in &cfg.outputs {
        if methods.iter().any(|m| m.name() == name) || name == NOISY {
            return Err(EvalError::ColumnTaken(name.clone()));
        }
        methods.push(Box::new(SavedOutputs::new(name.clone(), dir.clone())));
    }
    Ok(methods)
}

/// Run `cfg`'s protocol: find its cases (before anything is loaded), then
/// load the methods with `load`, run each on every case and measure the
/// outputs. The progress `start` makes once the methods are loaded hears
/// one `advance` per case and one `note` line with each case's scores.
/// Nothing is written but `cfg.dump`'s files.
pub fn run_protocol<P: Progress>(
    cfg: &EvalConfig,
    load: impl FnOnce() -> Result<Vec<Box<dyn MethodUnderTest>>, BoxError>,
    start: impl FnOnce() -> P,
) -> Result<Evaluation, EvalError> {
    let cases = find_cases(cfg)?;
    let methods = columns(cfg, load)?;
    let what = match &cases {
        Cases::Synthetic(images, recipe) => header::synthetic_description(images, recipe),
        Cases::Pairs(samples) => header::pairs_description(cfg, samples),
    };
    let head = header::header(cfg, &what);
    let methods: Vec<&dyn MethodUnderTest> = methods.iter().map(|m| m.as_ref()).collect();
    let opts = RunOptions {
        crop: cfg.crop,
        levels: LevelOverrides {
            black: None,
            white: cfg.white,
        },
        correct: cfg.correct,
        baseline: cfg.baseline,
        worst_count: cfg.worst_count,
        cast: false,
        dump: cfg.dump.clone(),
    };
    let progress = start();
    let Outcome { rows, worst, notes } = match &cases {
        Cases::Synthetic(images, r) => synthetic::run(images, r, &methods, &opts, &progress)?,
        Cases::Pairs(samples) => crate::dataset::run::run(samples, &methods, &opts, &progress)?,
    };
    let summary = summarise(&rows);
    let header = std::iter::once(head)
        .chain(notes.iter().map(|n| format!("note     {n}")))
        .collect::<Vec<_>>()
        .join("\n");
    let mut worst_columns: Vec<String> = Vec::new();
    if !cfg.baseline {
        worst_columns.push(NOISY.into());
    }
    worst_columns.extend(summary.methods.iter().cloned());
    worst_columns.push("reference".into());
    Ok(Evaluation {
        header,
        summary,
        rows,
        worst,
        worst_columns,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::{CaseInfo, FnMethod, RestoreError};
    use ndarray::{Array3, ArrayView3};
    use pgrf_core::NoProgress;
    use pgrf_scenes::chart::{render_chart, ChartSpec};

    fn identity() -> Box<dyn MethodUnderTest> {
        Box::new(FnMethod {
            name: "same".into(),
            f: |x: ArrayView3<f32>, _: &CaseInfo| -> Result<Array3<f32>, RestoreError> {
                Ok(x.to_owned())
            },
        })
    }

    #[test]
    fn a_synthetic_protocol_runs_from_its_config_and_writes_its_files() {
        let d = std::env::temp_dir().join(format!("pgrf-eval-config-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        let chart = render_chart(&ChartSpec {
            width: 128,
            height: 96,
            ..Default::default()
        })
        .unwrap();
        let clean = d.join("chart.dng");
        pgrf_raw::write_dng(&chart, &clean, &Default::default()).unwrap();
        let mut cfg = EvalConfig {
            protocol: DatasetKind::Synthetic,
            roots: vec![clean],
            scenes: "1-10".into(),
            list: None,
            keep_misaligned: false,
            synthetic: SyntheticSpec {
                isos: vec![1600],
                ratios: vec![100.0, 200.0],
                ..Default::default()
            },
            crop: None,
            white: None,
            correct: false,
            baseline: true,
            outputs: Vec::new(),
            dump: None,
            worst_count: 1,
            csv: Some(d.join("e.csv")),
            markdown: Some(d.join("e.md")),
            worst: None,
        };
        let ev = run_protocol(&cfg, || Ok(vec![identity()]), || NoProgress).unwrap();
        assert!(ev
            .header
            .starts_with("protocol synthetic: 1 clean files (chart.dng)"));
        assert!(ev.header.contains("\ncast     "), "{}", ev.header);
        assert_eq!(ev.summary.methods, vec![NOISY, "same"]);
        assert_eq!(ev.rows.len(), 2 * 2);
        // The identity is the noisy input, measured with the same protocol.
        assert_eq!(ev.rows[0].psnr, ev.rows[1].psnr);
        assert_eq!(ev.worst_columns, vec![NOISY, "same", "reference"]);
        let mut lines = Vec::new();
        ev.write(&cfg, &mut |l| lines.push(l.to_string())).unwrap();
        assert_eq!(lines.len(), 3, "{lines:?}");
        assert!(
            lines[2].contains("e_worst.png: chart.dng ISO 1600 x"),
            "{lines:?}"
        );
        let md = std::fs::read_to_string(d.join("e.md")).unwrap();
        assert!(md.starts_with("> protocol synthetic:"), "{md}");

        // Columns: an outside one may not take a method's name; the
        // loader's error comes back as it was.
        cfg.outputs = vec![("same".into(), d.clone())];
        let e = run_protocol(&cfg, || Ok(vec![identity()]), || NoProgress).err();
        assert!(matches!(e, Some(EvalError::ColumnTaken(n)) if n == "same"));
        let e = run_protocol(&cfg, || Err("no model".into()), || NoProgress).err();
        assert_eq!(e.unwrap().to_string(), "no model");
        // Cases are found before the methods are loaded.
        cfg.roots = vec![d.join("nope.dng")];
        let e = run_protocol(&cfg, || panic!("loaded"), || NoProgress).err();
        assert!(matches!(e, Some(EvalError::Dataset(_))));
        cfg.protocol = DatasetKind::Pairs;
        cfg.roots = vec![d.clone(), d.clone()];
        let e = run_protocol(&cfg, || panic!("loaded"), || NoProgress)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("takes one folder or file, got 2"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }
}
