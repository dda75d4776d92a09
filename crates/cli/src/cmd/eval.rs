//! `pgrf eval`: one or more models on a benchmark (ELD Sony A7S2, SID Sony,
//! a CSV of pairs, or dark captures synthesised from clean files), measured
//! under the ELD protocol, printed as the paper's tables print them (one row
//! per ratio, or per ISO and ratio, PSNR/SSIM per method, plus the colour
//! cast for synthetic captures), with per-image CSV, a Markdown table and a
//! PNG of the worst images.

use crate::progress::Bar;
use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use pgrf_core::NoProgress;
use pgrf_eval::dataset::run::{MethodFn, Outcome, RunOptions, Worst, NOISY};
use pgrf_eval::dataset::synthetic::{self, Synthetic};
use pgrf_eval::dataset::table::{csv, summarise};
use pgrf_eval::dataset::{eld, pairs, sid, DatasetKind, Sample};
use pgrf_eval::{cast, Protocol};
use pgrf_nn::backend::DeviceKind;
use pgrf_nn::infer::restorer::describe_sampler;
use pgrf_nn::infer::{restore_packed, Restore, SamplerChoice, Tiling};
use pgrf_noise::ModelKind;
use pgrf_raw::ndarray::{Array3, ArrayView3};
use pgrf_raw::{render_preview, unpack_normalized, PreviewOptions};
use pgrf_report::{write_montage, Panel};
use std::path::{Path, PathBuf};

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Baseline {
    /// A "noisy input" column: the amplified input clamped to [0, 1], measured like a model.
    Input,
    /// No baseline column.
    None,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum OnOff {
    On,
    Off,
}

#[derive(Args, Debug)]
#[command(after_help = "Protocols (stated again in the header of every run):\n\
  eld    ROOT/SonyA7S2/scene-1..10/IMG_00NN.ARW (or .dng); x100 = frames 4, 9, 14, x200 = 5, 10, 15; \
each paired with the nearest reference of frames 1, 6, 11, 16; ratio = ISO x exposure of the reference over the \
noisy frame's (EXIF); full images; illuminance correction on (ELD's test_ELD.py).\n\
  sid    pairs of ROOT/Sony_test_list.txt (or --list, SID or paired format); ratio = long / short exposure from \
the file names, capped at 300, rows x100/x250/x300; scenes 10034, 10045, 10172 left out (misaligned); centre \
512x512 of the packed planes; illuminance correction on (ELD's test_SID.py).\n\
  pairs  ROOT (a CSV, or a folder with pairs.csv) of noisy,reference,ratio (ratio empty: from EXIF); full \
images; no correction.\n\
  synthetic  --root FILE|FOLDER... of clean RAW files (or JPEG/PNG/TIFF photos: downscaled 2x and unprocessed \
into the Sony A7S2's camera space); each is made dark at every --iso x --ratio condition (default ISO \
800,1600,3200,6400 x ratio 50,100,200,300) with the --profile's noise (--noise pgrf|eld|pg) at that ISO: \
reference / ratio -> noise model -> x ratio, minus the capture's dark-level offset (the profile's black-level \
error at the ISO: the camera counts as calibrated, as with `pgrf enhance --calib`), clamped [0,1]; each file's own black/white levels; full images; no \
correction (the exposure is known). Capture seed = mix64(mix64(mix64(SEED ^ fnv1a64(file name)) ^ ISO) ^ f32 bits \
of the ratio) (SplitMix64 finaliser, 64-bit FNV-1a): the same command gives the same numbers, and adding files \
leaves the others' noise as it was. Rows per ISO and ratio; the CSV has one line per file, condition and method.\n\
  colour cast (synthetic): mean CIE76 chroma difference sqrt(da*^2 + db*^2) in dE*ab units (L* left out, so \
brightness errors do not count) of result vs reference over low-texture 16x16 packed-pixel blocks: blocks \
without a reference value >= 0.98 and with reference mean green >= 0.002, whose reference green coefficient of \
variation is at most the median of those blocks; each block's mean R, (G1+G2)/2, B converted to CIELAB (D65, \
white = 1) through the file's white balance and colour matrix (camera -> sRGB as pgrf preview, -> XYZ); the CSV \
adds the signed mean da* (+ magenta, - green) and db* (+ yellow, - blue). Results are clamped to [0,1] \
first; a file without white balance or colour matrix is measured with multipliers 1 or camera RGB as sRGB, \
and a `note` line in the header says so.\n\n\
Inputs are packed R,G1,B,G2, normalised by the files' black levels and white 16383 (eld, sid: ELD's \
pack_raw_bayer; pairs, synthetic: the files' white), multiplied by the ratio and clamped to [0,1]; references are clamped \
to [0,1]; a crop is applied before the network runs; then ELD's measurement (x255 floats, PSNR data range 255, \
SSIM 7x7). The `noisy input` column is measured without the correction, as ELD's res_in.")]
pub struct EvalArgs {
    /// Benchmark: eld, sid, pairs or synthetic.
    #[arg(long)]
    pub protocol: DatasetKind,
    /// Dataset folder (pairs: the CSV or its folder; synthetic: clean files and folders of them,
    /// several allowed: `--root A B` or `--root A --root B`).
    #[arg(long, required = true, num_args = 1..)]
    pub root: Vec<PathBuf>,
    /// Weight file from `pgrf train`; repeat for a comparison table.
    #[arg(long, short = 'm')]
    pub model: Vec<PathBuf>,
    /// Restorations made outside pgrf, as a column NAME: NAME=DIR reads DIR/KEY.output.npy for
    /// each case (KEY as `--dump` names it; packed (4, H, W) float32 or float64, the input's
    /// shape). Repeatable.
    #[arg(long, value_name = "NAME=DIR")]
    pub outputs: Vec<String>,
    /// Write each case's packed input and reference as DIR/KEY.input.npy and KEY.reference.npy,
    /// and KEY.json (synthetic: also KEY.capture.npy, the capture before clamping, and the true
    /// noise parameters), for methods outside pgrf (bench/vst_bm3d.py). The folder must exist.
    #[arg(long, value_name = "DIR")]
    pub dump: Option<PathBuf>,
    /// `input` adds the amplified noisy input as a "noisy input" column; `none` leaves it out.
    #[arg(long, default_value = "input")]
    pub noise_baseline: Baseline,
    /// ELD's least-squares brightness correction (default: the protocol's, on for eld and sid).
    #[arg(long)]
    pub illuminance_correct: Option<OnOff>,
    /// Centre crop of the packed planes before measuring: a side in packed pixels, or `none`
    /// (default: the protocol's, 512 for sid).
    #[arg(long)]
    pub crop: Option<String>,
    /// White level for normalising both files: a number, or `file` for each file's own
    /// (default: the protocol's, 16383 for eld and sid as ELD's pack_raw_bayer; file for pairs and
    /// synthetic).
    #[arg(long)]
    pub white: Option<String>,
    /// ELD scenes, e.g. 1-10 (default) or 1,2.
    #[arg(long, default_value = "1-10")]
    pub scenes: String,
    /// SID list file (default ROOT/Sony_test_list.txt).
    #[arg(long)]
    pub list: Option<PathBuf>,
    /// SID: keep the misaligned scenes 10034, 10045, 10172.
    #[arg(long)]
    pub keep_misaligned: bool,
    /// Per-image results as CSV.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// The table in Markdown.
    #[arg(long)]
    pub markdown: Option<PathBuf>,
    /// PNG of the worst images (by the first model's PSNR) side by side: noisy input, each
    /// model, reference. Default: next to --csv as NAME_worst.png; none without --csv.
    #[arg(long)]
    pub worst: Option<PathBuf>,
    /// Images in the worst-images PNG.
    #[arg(long, default_value_t = 4)]
    pub worst_count: usize,
    /// Tile side in packed pixels (default: as pgrf enhance chooses).
    #[arg(long)]
    pub tile: Option<usize>,
    /// cpu, or cuda (needs a build with `--features cuda`).
    #[arg(long, default_value = "cpu")]
    pub device: DeviceKind,
    /// Seed of the flow model's start noise, and (synthetic) the base of every capture's noise seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Synthetic: ISOs of the captures, comma-separated (default 800,1600,3200,6400).
    #[arg(long)]
    pub iso: Option<String>,
    /// Synthetic: exposure ratios, comma-separated, each >= 1 (default 50,100,200,300).
    #[arg(long)]
    pub ratio: Option<String>,
    /// Synthetic: camera noise profile: a built-in name, darktable:"MAKER MODEL", dng:FILE.dng or a JSON file (default sony-a7s2).
    #[arg(long)]
    pub profile: Option<String>,
    /// Synthetic: noise model, pgrf, eld or pg (default pgrf).
    #[arg(long)]
    pub noise: Option<ModelKind>,
    /// No per-image progress lines on stderr.
    #[arg(long, short)]
    pub quiet: bool,
}

fn parse_crop(a: &EvalArgs) -> Result<Option<usize>> {
    match a.crop.as_deref() {
        None => Ok(a.protocol.default_crop()),
        Some("none") | Some("0") => Ok(None),
        Some(v) => match v.parse::<usize>() {
            Ok(n) if n > 0 => Ok(Some(n)),
            _ => bail!("--crop {v:?}: expected a side in packed pixels or `none`"),
        },
    }
}

fn parse_white(a: &EvalArgs) -> Result<Option<u32>> {
    match a.white.as_deref() {
        None => Ok(a.protocol.default_white()),
        Some("file") => Ok(None),
        Some(v) => match v.parse::<u32>() {
            Ok(n) if n > 0 => Ok(Some(n)),
            _ => bail!("--white {v:?}: expected a level in DN or `file`"),
        },
    }
}

/// What a file-pair run measures, for the header's first line.
fn pairs_description(a: &EvalArgs, samples: &[Sample]) -> String {
    let what = match a.protocol {
        DatasetKind::Eld => format!(
            "ELD Sony A7S2, scenes {}: x100 = frames 4,9,14, x200 = frames 5,10,15, reference = nearest of frames 1,6,11,16, ratio = ISO x exposure of reference / noisy (EXIF)",
            a.scenes
        ),
        DatasetKind::Sid => format!(
            "SID Sony, {}: ratio = long / short exposure from file names, capped at 300; {}",
            a.list
                .as_ref()
                .map(|p| p.display().to_string())
                .unwrap_or_else(|| sid::DEFAULT_LIST.into()),
            if a.keep_misaligned {
                "misaligned 10034, 10045, 10172 kept"
            } else {
                "misaligned 10034, 10045, 10172 excluded"
            }
        ),
        DatasetKind::Pairs => format!("pairs of {}", a.root[0].display()),
        DatasetKind::Synthetic => "synthetic captures".into(),
    };
    format!("{what}; {} images", samples.len())
}

/// What a synthetic run measures, for the header's first line.
fn synthetic_description(images: &[synthetic::Image], synth: &Synthetic) -> String {
    let names: Vec<&str> = images.iter().map(|i| i.id.as_str()).collect();
    format!(
        "{} clean files ({}); {}; {} captures",
        images.len(),
        names.join(", "),
        synth.describe(),
        images.len() * synth.conditions.len()
    )
}

/// The header: what is measured (`what`), how, and for synthetic runs the
/// colour-cast definition.
fn header(
    a: &EvalArgs,
    what: &str,
    crop: Option<usize>,
    correct: bool,
    white: Option<u32>,
) -> String {
    let synthetic = a.protocol == DatasetKind::Synthetic;
    let crop = match crop {
        Some(c) => {
            format!("centre {c}x{c} of the packed planes (input cropped before the network)")
        }
        None => "full image".into(),
    };
    let white = match white {
        Some(w) => format!("white {w}"),
        None => "white from each file".into(),
    };
    let input = if synthetic {
        "capture = reference / ratio through the noise model, x ratio, minus its dark-level offset (the profile's black-level error at the ISO, calibrated), clamped [0,1]"
    } else {
        "input x ratio clamped [0,1]"
    };
    let mut s = format!(
        "protocol {}: {what}; {crop}\nmeasure  packed R,G1,B,G2, black per channel from the files, {white}; {input}, reference clamped [0,1]; {}{}",
        a.protocol,
        Protocol::eld(correct).describe(),
        if correct && a.noise_baseline == Baseline::Input {
            format!("; `{NOISY}` without the correction (ELD's res_in)")
        } else {
            String::new()
        }
    );
    if synthetic {
        s.push_str(&format!("\ncast     {}", cast::DEFINITION));
    }
    s
}

/// The file-pair protocols take exactly one --root.
fn one_root(a: &EvalArgs) -> Result<&Path> {
    match a.root.as_slice() {
        [r] => Ok(r),
        r => bail!(
            "--root: the {} protocol takes one folder or file, got {}",
            a.protocol,
            r.len()
        ),
    }
}

fn walk(a: &EvalArgs) -> Result<Vec<Sample>> {
    let root = one_root(a)?;
    Ok(match a.protocol {
        DatasetKind::Eld => {
            let scenes = eld::parse_scenes(&a.scenes).map_err(anyhow::Error::msg)?;
            eld::walk(root, &scenes)?
        }
        DatasetKind::Sid => sid::walk(root, a.list.as_deref(), a.keep_misaligned)?,
        DatasetKind::Pairs => pairs::walk(root)?,
        DatasetKind::Synthetic => bail!("the synthetic protocol has no file pairs to walk"),
    })
}

/// The synthetic recipe from --iso, --ratio, --profile, --noise and --seed.
fn synthetic_recipe(a: &EvalArgs) -> Result<Synthetic> {
    let isos = match &a.iso {
        Some(t) => synthetic::parse_isos(t)?,
        None => synthetic::DEFAULT_ISOS.to_vec(),
    };
    let ratios = match &a.ratio {
        Some(t) => synthetic::parse_ratios(t)?,
        None => synthetic::DEFAULT_RATIOS.to_vec(),
    };
    Ok(Synthetic::new(
        a.profile.as_deref().unwrap_or("sony-a7s2"),
        a.noise.unwrap_or_default(),
        synthetic::grid(&isos, &ratios),
        a.seed,
    )?)
}

/// `--outputs NAME=DIR` entries, each folder checked to exist.
fn parse_outputs(items: &[String]) -> Result<Vec<(String, PathBuf)>> {
    items
        .iter()
        .map(|item| {
            let Some((name, dir)) = item.split_once('=') else {
                bail!("--outputs {item:?}: expected NAME=DIR");
            };
            let (name, dir) = (name.trim(), PathBuf::from(dir));
            if name.is_empty() {
                bail!("--outputs {item:?}: the column name before = is empty");
            }
            if !dir.is_dir() {
                bail!("--outputs {item:?}: {} is not a folder", dir.display());
            }
            Ok((name.to_string(), dir))
        })
        .collect()
}

/// The outside method's restoration of case `key`: DIR/KEY.output.npy, of
/// the input's shape (a larger file is refused before it is read).
fn read_output(
    dir: &Path,
    key: &str,
    input: ArrayView3<f32>,
) -> std::result::Result<Array3<f32>, String> {
    let path = dir.join(format!("{key}.output.npy"));
    let out = pgrf_eval::npy::read(&path, 8 * input.len() as u64 + 65_536)?;
    if out.dim() != input.dim() {
        return Err(format!(
            "{}: shape {:?}, the input is {:?}",
            path.display(),
            out.dim(),
            input.dim()
        ));
    }
    Ok(out)
}

fn write_file(path: &Path, text: &str) -> Result<()> {
    pgrf_core::write_atomic(path, text.as_bytes()).with_context(|| format!("{}", path.display()))
}

pub fn run(a: &EvalArgs) -> Result<()> {
    pgrf_nn::infer::check_tiling_args(a.tile, None)?;
    let crop = parse_crop(a)?;
    let white = parse_white(a)?;
    let levels = pgrf_raw::LevelOverrides { black: None, white };
    let correct = match a.illuminance_correct {
        Some(v) => v == OnOff::On,
        None => a.protocol.default_correct(),
    };
    let baseline = a.noise_baseline == Baseline::Input;
    if a.model.is_empty() && a.outputs.is_empty() && !baseline {
        bail!("nothing to evaluate: give --model (or keep the noisy-input baseline)");
    }
    if let Some(d) = &a.dump {
        if !d.is_dir() {
            bail!("--dump {}: no such folder", d.display());
        }
    }
    let outside = parse_outputs(&a.outputs)?;
    let synthetic = a.protocol == DatasetKind::Synthetic;
    if !synthetic {
        for (flag, given) in [
            ("--iso", a.iso.is_some()),
            ("--ratio", a.ratio.is_some()),
            ("--profile", a.profile.is_some()),
            ("--noise", a.noise.is_some()),
        ] {
            if given {
                bail!("{flag} goes with --protocol synthetic only");
            }
        }
    }
    // What is measured: file pairs, or clean files and the synthetic recipe.
    let (samples, images, recipe) = if synthetic {
        let recipe = synthetic_recipe(a)?;
        (Vec::new(), synthetic::walk(&a.root)?, Some(recipe))
    } else {
        (walk(a)?, Vec::new(), None)
    };
    a.device.check_available().map_err(anyhow::Error::msg)?;
    let mut models: Vec<(String, Box<dyn Restore>)> = Vec::new();
    for m in &a.model {
        let r = crate::shipped::load_model(m, SamplerChoice::default(), a.device)
            .with_context(|| format!("--model {}", m.display()))?;
        let mut name = m
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| m.display().to_string());
        while models.iter().any(|(n, _)| *n == name) || name == NOISY {
            name.push('\'');
        }
        if !a.quiet {
            eprintln!(
                "model {name}: {} ({})",
                r.meta().arch.describe(),
                describe_sampler(r.as_ref())
            );
        }
        models.push((name, r));
    }
    let (what, cases, units) = match &recipe {
        Some(r) => (
            synthetic_description(&images, r),
            images.len() * r.conditions.len(),
            "captures",
        ),
        None => (pairs_description(a, &samples), samples.len(), "images"),
    };
    let head = header(a, &what, crop, correct, white);
    let bar = Bar::new("eval", cases as u64, units, a.quiet);
    let tiling = Tiling {
        tile: a.tile,
        overlap: None,
        seed: a.seed,
        device: a.device,
    };
    let mut closures: Vec<(String, Box<MethodFn>)> = models
        .iter()
        .map(|(name, r)| {
            let f = Box::new(move |x: ArrayView3<f32>, _: &str| {
                restore_packed(r.as_ref(), x, &tiling, &NoProgress)
                    .map(|o| o.output)
                    .map_err(|e| e.to_string())
            }) as Box<MethodFn>;
            (name.clone(), f)
        })
        .collect();
    for (name, dir) in outside {
        if closures.iter().any(|(n, _)| *n == name) || name == NOISY {
            bail!("--outputs {name}=...: the name is taken by another column");
        }
        let f = Box::new(move |x: ArrayView3<f32>, key: &str| read_output(&dir, key, x))
            as Box<MethodFn>;
        closures.push((name, f));
    }
    let methods: Vec<(String, &MethodFn)> = closures
        .iter()
        .map(|(name, f)| (name.clone(), f.as_ref()))
        .collect();
    let opts = RunOptions {
        crop,
        levels,
        correct,
        baseline,
        worst_count: a.worst_count,
        cast: false,
        dump: a.dump.clone(),
    };
    let Outcome { rows, worst, notes } = match &recipe {
        Some(r) => synthetic::run(&images, r, &methods, &opts, &bar)?,
        None => pgrf_eval::dataset::run::run(&samples, &methods, &opts, &bar)?,
    };
    let summary = summarise(&rows);
    let head = std::iter::once(head)
        .chain(notes.iter().map(|n| format!("note     {n}")))
        .collect::<Vec<_>>()
        .join("\n");
    println!("{head}");
    print!("{}", summary.text());
    if let Some(p) = &a.csv {
        write_file(p, &csv(&rows))?;
        eprintln!("wrote {}", p.display());
    }
    if let Some(p) = &a.markdown {
        let text = format!(
            "{}\n\n{}",
            head.lines()
                .map(|l| format!("> {l}"))
                .collect::<Vec<_>>()
                .join("  \n"),
            summary.markdown()
        );
        write_file(p, &text)?;
        eprintln!("wrote {}", p.display());
    }
    let worst_path = a.worst.clone().or_else(|| {
        a.csv.as_ref().map(|c| {
            let stem = c.file_stem().unwrap_or_default().to_string_lossy();
            c.with_file_name(format!("{stem}_worst.png"))
        })
    });
    if let Some(p) = worst_path {
        if !worst.is_empty() {
            let mut cols: Vec<String> = Vec::new();
            if !baseline {
                cols.push(NOISY.into());
            }
            cols.extend(summary.methods.iter().cloned());
            cols.push("reference".into());
            write_worst(&worst, &cols, &p)?;
            eprintln!(
                "wrote {}: {} (columns: {})",
                p.display(),
                worst
                    .iter()
                    .map(|w| w.id.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
                cols.join(", ")
            );
        }
    }
    Ok(())
}

/// Rows of previews (one per worst image), each captioned with its image
/// id and column name.
fn write_worst(worst: &[Worst], cols: &[String], path: &Path) -> Result<()> {
    let mut rows: Vec<Vec<Panel>> = Vec::new();
    for w in worst {
        let mut row = Vec::new();
        for (t, col) in w.tiles.iter().zip(cols) {
            let f = unpack_normalized(t.view(), &w.template)?;
            row.push(Panel {
                caption: format!("{}: {col}", w.id),
                image: render_preview(&f, &PreviewOptions::default())?,
            });
        }
        rows.push(row);
    }
    write_montage(path, &rows).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}
