//! An evaluation run: every sample of a benchmark through every method,
//! measured under the protocol, to per-image rows (and the thumbnails of
//! the worst images). `pgrf eval` only parses, calls this and prints.
//!
//! Methods are [`MethodUnderTest`]s, from a packed, amplified input to its
//! restoration, so this crate needs no network framework: pgrf-nn wraps its
//! models.

use super::table::Row;
use super::{centre_crop, load_pair, DatasetError, LoadedPair, Result, Sample};
use crate::method::{CaseInfo, MethodUnderTest};
use crate::metrics::{black_level, colour_cast, evaluate, CameraColour, MetricError, Protocol};
use ndarray::{Array3, ArrayView3};
use pgrf_core::Progress;
use pgrf_raw::{LevelOverrides, RawFrame};

/// Name of the amplified-input baseline in tables.
pub const NOISY: &str = "noisy input";

/// Side of the centre thumbnails kept for the worst-images picture (packed
/// pixels).
pub(crate) const THUMB: usize = 128;

/// How a run measures.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Centre crop of the packed planes, applied before the methods run.
    pub crop: Option<usize>,
    /// Levels overriding the files' (ELD's white 16383).
    pub levels: LevelOverrides,
    /// ELD's illuminance correction for the methods (never for the noisy
    /// input, which is measured as ELD's `res_in`).
    pub correct: bool,
    /// Add the amplified noisy input as a column.
    pub baseline: bool,
    /// How many worst images (by the first method's PSNR) to keep.
    pub worst_count: usize,
    /// Measure the colour cast ([`crate::cast`]) of every output too.
    pub cast: bool,
    /// Write every case's input and reference (and, when synthesised, the
    /// unclamped capture and its true noise parameters) to this folder, for
    /// methods outside pgrf (`KEY.input.npy`, `KEY.reference.npy`, `KEY.json`, `KEY.capture.npy`).
    pub dump: Option<std::path::PathBuf>,
}

/// One of the worst images: its thumbnails, in column order.
pub struct Worst {
    /// PSNR of the ranking method.
    pub(crate) score: f64,
    /// The sample's id.
    pub id: String,
    /// A frame of the thumbnails' size with the reference's CFA and levels,
    /// to unpack them for previews.
    pub template: RawFrame,
    /// Noisy input, each method, reference (`THUMB` packed pixels square).
    pub tiles: Vec<Array3<f32>>,
}

/// What a run measured.
pub struct Outcome {
    /// One row per image and method (the noisy input included).
    pub rows: Vec<Row>,
    /// The worst images, worst first.
    pub worst: Vec<Worst>,
    /// Lines for the header about how some cases were measured (e.g. a
    /// file without a colour matrix).
    pub notes: Vec<String>,
}

fn thumb(a: ArrayView3<f32>) -> Array3<f32> {
    centre_crop(a, Some(THUMB)).to_owned()
}

/// One case of a run: a loaded pair and what its rows and messages say
/// about it.
pub(crate) struct Case {
    pub(crate) pair: LoadedPair,
    /// The rows' common fields (method and scores are filled per method).
    pub(crate) row: Row,
    /// What a failing method's error names (the noisy file).
    pub(crate) source: String,
    /// The case in error messages and the worst-images picture.
    pub(crate) title: String,
    /// The case in the progress line, after `[i/n]`.
    pub(crate) line: String,
    /// What the case's files are named after ([`case_key`]).
    pub(crate) key: String,
    /// A synthesised case's capture before clamping and the noise it was
    /// drawn with, for `--dump`.
    pub(crate) synthesis: Option<Synthesis>,
}

/// What a synthesised case adds to its dump: the amplified capture before
/// clamping (a classical method wants the values below 0 and above 1) and
/// the true noise parameters, as JSON.
pub(crate) struct Synthesis {
    pub(crate) capture: Array3<f32>,
    pub(crate) noise: serde_json::Value,
}

/// A file-name-safe key for a case: its title with every character other
/// than ASCII letters, digits, '.', '-' and '_' replaced by '_'.
pub fn case_key(title: &str) -> String {
    title
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_') {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Write case `key`'s files into `dir`: `KEY.input.npy` (the methods'
/// input), `KEY.reference.npy`, `KEY.json` (title, ratio and, when
/// synthesised, the noise), and for a synthesised case `KEY.capture.npy`.
/// Arrays are packed `(4, H, W)` float32 after any crop.
fn dump_case(
    dir: &std::path::Path,
    case: &Case,
    input: ArrayView3<f32>,
    reference: ArrayView3<f32>,
    crop: Option<usize>,
) -> Result<()> {
    let at = |e: crate::npy::NpyError| DatasetError(format!("--dump: {e}"));
    let key = &case.key;
    crate::npy::write(&dir.join(format!("{key}.input.npy")), input).map_err(at)?;
    crate::npy::write(&dir.join(format!("{key}.reference.npy")), reference).map_err(at)?;
    let mut meta = serde_json::json!({
        "case": case.title,
        "ratio": case.pair.ratio,
        "shape": input.shape(),
        "input": "amplified capture clipped at 1 (values below black kept: a network that reads them clamped clamps them itself), normalised by the reference's levels",
    });
    if let Some(s) = &case.synthesis {
        let capture = centre_crop(s.capture.view(), crop);
        crate::npy::write(&dir.join(format!("{key}.capture.npy")), capture).map_err(at)?;
        meta["noise"] = s.noise.clone();
        meta["capture"] = "the same capture before clamping".into();
    }
    let text = serde_json::to_string_pretty(&meta).expect("JSON of plain values");
    pgrf_core::write_atomic(&dir.join(format!("{key}.json")), text.as_bytes())
        .map_err(|e| DatasetError(format!("--dump: {e}")))
}

/// Run `methods` (in column order) over `samples`.
/// `progress` hears one `advance` per image and one `note` line with each
/// image's scores.
pub fn run(
    samples: &[Sample],
    methods: &[&dyn MethodUnderTest],
    opts: &RunOptions,
    progress: &dyn Progress,
) -> Result<Outcome> {
    let load = |i: usize| -> Result<Case> {
        let smp = &samples[i];
        let pair = load_pair(smp, &opts.levels)?;
        Ok(Case {
            row: Row {
                protocol: smp.kind.name().into(),
                id: smp.id.clone(),
                group: smp.group,
                ratio: pair.ratio,
                noisy: smp.noisy.display().to_string(),
                reference: smp.reference.display().to_string(),
                method: String::new(),
                psnr: f64::NAN,
                ssim: f64::NAN,
                gain: None,
                iso: None,
                seed: None,
                cast: None,
                black: None,
                noise: None,
            },
            source: smp.noisy.display().to_string(),
            title: smp.id.clone(),
            line: format!("{} x{:.1}", smp.id, pair.ratio),
            key: case_key(&format!("{}_x{}", smp.id, pair.ratio)),
            synthesis: None,
            pair,
        })
    };
    run_cases(samples.len(), "images", load, methods, opts, progress)
}

/// The one evaluation loop: case `i` of `n` from `load(i)` (called in
/// order), every method on its input, every output measured.
pub(crate) fn run_cases(
    n: usize,
    units: &str,
    mut load: impl FnMut(usize) -> Result<Case>,
    methods: &[&dyn MethodUnderTest],
    opts: &RunOptions,
    progress: &dyn Progress,
) -> Result<Outcome> {
    let mut rows = Vec::new();
    let mut worst: Vec<Worst> = Vec::new();
    progress.start(n as u64, units);
    for i in 0..n {
        let case = load(i)?;
        let pair = &case.pair;
        // ELD crops input and reference before the network runs.
        let input = centre_crop(pair.input.view(), opts.crop).to_owned();
        let reference = centre_crop(pair.reference.view(), opts.crop);
        if let Some(dir) = &opts.dump {
            dump_case(dir, &case, input.view(), reference, opts.crop)?;
        }
        let outputs = restore_case(&case, &input, methods, opts)?;
        let line = format!("[{}/{n}] {}", i + 1, case.line);
        let (line, first) = measure_case(&case, &outputs, reference, opts, line, &mut rows)?;
        progress.note(&line);
        progress.advance(1);
        if opts.worst_count > 0 {
            worst.push(worst_of(&case, &input, &outputs, reference, opts, first));
            worst.sort_by(|x, y| x.score.total_cmp(&y.score));
            worst.truncate(opts.worst_count);
        }
    }
    progress.finish();
    Ok(Outcome {
        rows,
        worst,
        notes: Vec::new(),
    })
}

/// Every method's output on the case's (cropped) `input`, after the noisy
/// input itself when the baseline is asked for.
fn restore_case<'m>(
    case: &Case,
    input: &Array3<f32>,
    methods: &[&'m dyn MethodUnderTest],
    opts: &RunOptions,
) -> Result<Vec<(&'m str, Array3<f32>)>> {
    let mut outputs: Vec<(&str, Array3<f32>)> = Vec::new();
    if opts.baseline {
        outputs.push((NOISY, input.clone()));
    }
    let info = CaseInfo {
        key: &case.key,
        ratio: case.pair.ratio,
        noise: case.pair.noise.as_ref(),
    };
    for m in methods {
        let name = m.name();
        let out = m
            .restore(input.view(), &info)
            .map_err(|e| DatasetError(format!("{}: model {name}: {e}", case.source)))?;
        outputs.push((name, out));
    }
    Ok(outputs)
}

/// Every output measured against `reference`: one row each appended to
/// `rows`, and each method's scores appended to the progress `line`.
/// Also the score the worst-images ranking follows: the first method's
/// PSNR (the noisy input's when there is none).
fn measure_case(
    case: &Case,
    outputs: &[(&str, Array3<f32>)],
    reference: ArrayView3<f32>,
    opts: &RunOptions,
    mut line: String,
    rows: &mut Vec<Row>,
) -> Result<(String, Option<f64>)> {
    let protocol = Protocol::eld(opts.correct);
    let plain = Protocol::eld(false);
    let colour = opts
        .cast
        .then(|| CameraColour::of(&case.pair.reference_frame));
    let rank = outputs.iter().position(|(n, _)| *n != NOISY).unwrap_or(0);
    let mut first = None;
    for (k, (name, out)) in outputs.iter().enumerate() {
        let p = if *name == NOISY { &plain } else { &protocol };
        let at = |e: MetricError| DatasetError(format!("{}: {e}", case.title));
        let sc = evaluate(out.view(), reference, p).map_err(at)?;
        // A monochrome frame has no colour to cast.
        let cast = match &colour {
            Some(c) if !case.pair.reference_frame.mono => {
                colour_cast(out.view(), reference, c).map_err(at)?
            }
            _ => None,
        };
        let black = colour
            .is_some()
            .then(|| black_level(out.view(), reference))
            .flatten();
        if k == rank {
            first = Some(sc.psnr);
        }
        line.push_str(&format!("  {name} {:.2}/{:.4}", sc.psnr, sc.ssim));
        if let Some(c) = &cast {
            line.push_str(&format!("/{:.2}", c.dab));
        }
        rows.push(Row {
            method: name.to_string(),
            psnr: sc.psnr,
            ssim: sc.ssim,
            gain: sc.gain,
            cast,
            black,
            ..case.row.clone()
        });
    }
    Ok((line, first))
}

/// The case as a row of the worst-images picture: thumbnails of the input,
/// every output and the reference, ranked by `first`.
fn worst_of(
    case: &Case,
    input: &Array3<f32>,
    outputs: &[(&str, Array3<f32>)],
    reference: ArrayView3<f32>,
    opts: &RunOptions,
    first: Option<f64>,
) -> Worst {
    let mut tiles: Vec<Array3<f32>> = outputs.iter().map(|(_, o)| thumb(o.view())).collect();
    if !opts.baseline {
        tiles.insert(0, thumb(input.view()));
    }
    tiles.push(thumb(reference));
    let (_, th, tw) = tiles[0].dim();
    let mut template = case.pair.reference_frame.clone();
    template.width = 2 * tw;
    template.height = 2 * th;
    template.mosaic = vec![0; 4 * tw * th];
    Worst {
        score: first.unwrap_or(f64::INFINITY),
        id: case.title.clone(),
        template,
        tiles,
    }
}
