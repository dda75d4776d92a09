//! An evaluation run: every sample of a benchmark through every method,
//! measured under the protocol, to per-image rows (and the thumbnails of
//! the worst images). `pgrf eval` only parses, calls this and prints.
//!
//! Methods are closures from a packed, amplified input to its restoration,
//! so this crate needs no network framework: the CLI wraps its models.

use super::table::Row;
use super::{centre_crop, load_pair, DatasetError, Result, Sample};
use crate::metrics::{evaluate, Protocol};
use ndarray::{Array3, ArrayView3};
use pgrf_core::Progress;
use pgrf_raw::{LevelOverrides, RawFrame};

/// Name of the amplified-input baseline in tables.
pub const NOISY: &str = "noisy input";

/// Side of the centre thumbnails kept for the worst-images picture (packed
/// pixels).
pub(crate) const THUMB: usize = 128;

/// A method under evaluation: packed `(4, h, w)` amplified input in [0, 1]
/// to its restoration, or a one-line reason.
pub type MethodFn<'a> = dyn Fn(ArrayView3<f32>) -> std::result::Result<Array3<f32>, String> + 'a;

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
}

fn thumb(a: ArrayView3<f32>) -> Array3<f32> {
    centre_crop(a, Some(THUMB)).to_owned()
}

/// Run `methods` (name and closure, in column order) over `samples`.
/// `progress` hears one `advance` per image and one `note` line with each
/// image's scores.
pub fn run(
    samples: &[Sample],
    methods: &[(String, &MethodFn)],
    opts: &RunOptions,
    progress: &dyn Progress,
) -> Result<Outcome> {
    let protocol = Protocol::eld(opts.correct);
    let plain = Protocol::eld(false);
    let n = samples.len();
    let mut rows = Vec::new();
    let mut worst: Vec<Worst> = Vec::new();
    progress.start(n as u64, "images");
    for (i, smp) in samples.iter().enumerate() {
        let pair = load_pair(smp, &opts.levels)?;
        // ELD crops input and reference before the network runs.
        let input = centre_crop(pair.input.view(), opts.crop).to_owned();
        let reference = centre_crop(pair.reference.view(), opts.crop);
        let mut outputs: Vec<(&str, Array3<f32>)> = Vec::new();
        if opts.baseline {
            outputs.push((NOISY, input.clone()));
        }
        for (name, f) in methods {
            let out = f(input.view())
                .map_err(|e| DatasetError(format!("{}: model {name}: {e}", smp.noisy.display())))?;
            outputs.push((name, out));
        }
        // The worst-images ranking follows the first method (the noisy
        // input when there is none).
        let rank = outputs.iter().position(|(n, _)| *n != NOISY).unwrap_or(0);
        let mut first = None;
        let mut line = format!("[{}/{n}] {} x{:.1}", i + 1, smp.id, pair.ratio);
        for (k, (name, out)) in outputs.iter().enumerate() {
            let p = if *name == NOISY { &plain } else { &protocol };
            let sc = evaluate(out.view(), reference, p)
                .map_err(|e| DatasetError(format!("{}: {e}", smp.id)))?;
            if k == rank {
                first = Some(sc.psnr);
            }
            line.push_str(&format!("  {name} {:.2}/{:.4}", sc.psnr, sc.ssim));
            rows.push(Row {
                protocol: smp.kind.name().into(),
                id: smp.id.clone(),
                group: smp.group,
                ratio: pair.ratio,
                noisy: smp.noisy.display().to_string(),
                reference: smp.reference.display().to_string(),
                method: name.to_string(),
                psnr: sc.psnr,
                ssim: sc.ssim,
                gain: sc.gain,
            });
        }
        progress.note(&line);
        progress.advance(1);
        if opts.worst_count > 0 {
            let mut tiles: Vec<Array3<f32>> =
                outputs.iter().map(|(_, o)| thumb(o.view())).collect();
            if !opts.baseline {
                tiles.insert(0, thumb(input.view()));
            }
            tiles.push(thumb(reference));
            let (_, th, tw) = tiles[0].dim();
            let mut template = pair.reference_frame.clone();
            template.width = 2 * tw;
            template.height = 2 * th;
            template.mosaic = vec![0; 4 * tw * th];
            worst.push(Worst {
                score: first.unwrap_or(f64::INFINITY),
                id: smp.id.clone(),
                template,
                tiles,
            });
            worst.sort_by(|x, y| x.score.total_cmp(&y.score));
            worst.truncate(opts.worst_count);
        }
    }
    progress.finish();
    Ok(Outcome { rows, worst })
}
