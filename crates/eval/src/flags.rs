//! `pgrf eval`'s protocol flags (the `clap` feature) and the evaluation
//! they describe, every flag checked: kept beside the protocols, so a new
//! option is added in one crate. The methods (`--model`, its device and
//! tiling) are the caller's: this crate measures any producer's output.

use crate::dataset::synthetic::{self, DEFAULT_ISOS, DEFAULT_RATIOS};
use crate::dataset::DatasetKind;
use crate::evaluation::{EvalConfig, EvalError, SyntheticSpec};
use clap::ValueEnum;
use pgrf_noise::ModelKind;
use std::path::PathBuf;

/// The protocols, stated as `pgrf eval --help` ends (and again in the
/// header of every run).
pub const PROTOCOLS_HELP: &str = "Protocols (stated again in the header of every run):\n\
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
800,1600,3200,6400 x ratio 50,100,200,300) with the --profile's noise (--noise-model pgrf|eld|pg) at that ISO: \
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
SSIM 7x7). The `noisy input` column is measured without the correction, as ELD's res_in.";

/// Whether the noisy input is measured as a column of its own.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Baseline {
    /// A "noisy input" column: the amplified input clamped to [0, 1], measured like a model.
    Input,
    /// No baseline column.
    None,
}

/// A switch given as `on` or `off`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum OnOff {
    /// On.
    On,
    /// Off.
    Off,
}

/// `pgrf eval`'s flags but the methods'.
#[derive(clap::Args, Debug)]
pub struct EvalFlags {
    /// Benchmark: eld, sid, pairs or synthetic.
    #[arg(long)]
    pub protocol: DatasetKind,
    /// Dataset folder (pairs: the CSV or its folder; synthetic: clean files and folders of them,
    /// several allowed: `--root A B` or `--root A --root B`).
    #[arg(long, required = true, num_args = 1..)]
    pub root: Vec<PathBuf>,
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
    /// Synthetic: noise model, pgrf, eld or pg (default pgrf; `--noise`, its old name, still works).
    #[arg(long = "noise-model", alias = "noise")]
    pub noise: Option<ModelKind>,
    /// Synthetic: hand the methods each capture as an uncalibrated camera writes it, its dark-level offset (the profile's black-level error) kept, instead of subtracted as a calibration would.
    #[arg(long)]
    pub uncalibrated: bool,
    /// Synthetic: tell noise-aware models the blind estimate of each capture's noise (`pgrf_noise::estimate`, what `pgrf enhance` falls back to for a camera it knows nothing of) instead of its true parameters; the CSV has both.
    #[arg(long)]
    pub blind_noise: bool,
    /// No per-image progress lines on stderr.
    #[arg(long, short)]
    pub quiet: bool,
}

/// A refused flag value, named.
fn bad(flag: &'static str, message: String) -> EvalError {
    EvalError::BadOption { flag, message }
}

impl EvalFlags {
    fn crop(&self) -> Result<Option<usize>, EvalError> {
        match self.crop.as_deref() {
            None => Ok(self.protocol.default_crop()),
            Some("none") | Some("0") => Ok(None),
            Some(v) => match v.parse::<usize>() {
                Ok(n) if n > 0 => Ok(Some(n)),
                _ => Err(bad(
                    "--crop",
                    format!("--crop {v:?}: expected a side in packed pixels or `none`"),
                )),
            },
        }
    }

    fn white(&self) -> Result<Option<u32>, EvalError> {
        match self.white.as_deref() {
            None => Ok(self.protocol.default_white()),
            Some("file") => Ok(None),
            Some(v) => match v.parse::<u32>() {
                Ok(n) if n > 0 => Ok(Some(n)),
                _ => Err(bad(
                    "--white",
                    format!("--white {v:?}: expected a level in DN or `file`"),
                )),
            },
        }
    }

    /// `--outputs NAME=DIR` entries, each folder checked to exist.
    fn outputs(&self) -> Result<Vec<(String, PathBuf)>, EvalError> {
        self.outputs
            .iter()
            .map(|item| {
                let Some((name, dir)) = item.split_once('=') else {
                    return Err(bad(
                        "--outputs",
                        format!("--outputs {item:?}: expected NAME=DIR"),
                    ));
                };
                let (name, dir) = (name.trim(), PathBuf::from(dir));
                if name.is_empty() {
                    return Err(bad(
                        "--outputs",
                        format!("--outputs {item:?}: the column name before = is empty"),
                    ));
                }
                if !dir.is_dir() {
                    return Err(bad(
                        "--outputs",
                        format!("--outputs {item:?}: {} is not a folder", dir.display()),
                    ));
                }
                Ok((name.to_string(), dir))
            })
            .collect()
    }

    /// The synthetic captures from --iso, --ratio, --profile, --noise-model and
    /// --seed; those flags are refused with the other protocols.
    fn synthetic_spec(&self) -> Result<SyntheticSpec, EvalError> {
        if self.protocol != DatasetKind::Synthetic {
            for (flag, given) in [
                ("--iso", self.iso.is_some()),
                ("--ratio", self.ratio.is_some()),
                ("--profile", self.profile.is_some()),
                ("--noise-model", self.noise.is_some()),
                ("--uncalibrated", self.uncalibrated),
                ("--blind-noise", self.blind_noise),
            ] {
                if given {
                    return Err(bad(
                        flag,
                        format!("{flag} goes with --protocol synthetic only"),
                    ));
                }
            }
            return Ok(SyntheticSpec::default());
        }
        Ok(SyntheticSpec {
            isos: match &self.iso {
                Some(t) => synthetic::parse_isos(t)?,
                None => DEFAULT_ISOS.to_vec(),
            },
            ratios: match &self.ratio {
                Some(t) => synthetic::parse_ratios(t)?,
                None => DEFAULT_RATIOS.to_vec(),
            },
            profile: self.profile.clone().unwrap_or_else(|| "sony-a7s2".into()),
            noise: self.noise.unwrap_or_default(),
            seed: self.seed,
            uncalibrated: self.uncalibrated,
            blind_noise: self.blind_noise,
            // The caller's (the command line's global --darktable-profiles).
            darktable: None,
        })
    }

    /// The evaluation the flags describe, every flag checked; `methods`:
    /// whether the caller has methods of its own to measure (without them
    /// and without the baseline there is nothing to evaluate).
    pub fn config(&self, methods: bool) -> Result<EvalConfig, EvalError> {
        let crop = self.crop()?;
        let white = self.white()?;
        let correct = match self.illuminance_correct {
            Some(v) => v == OnOff::On,
            None => self.protocol.default_correct(),
        };
        let baseline = self.noise_baseline == Baseline::Input;
        if !methods && self.outputs.is_empty() && !baseline {
            return Err(bad(
                "--model",
                "nothing to evaluate: give --model (or keep the noisy-input baseline)".into(),
            ));
        }
        if let Some(d) = &self.dump {
            if !d.is_dir() {
                return Err(bad(
                    "--dump",
                    format!("--dump {}: no such folder", d.display()),
                ));
            }
        }
        let outputs = self.outputs()?;
        Ok(EvalConfig {
            protocol: self.protocol,
            roots: self.root.clone(),
            scenes: self.scenes.clone(),
            list: self.list.clone(),
            keep_misaligned: self.keep_misaligned,
            synthetic: self.synthetic_spec()?,
            crop,
            white,
            correct,
            baseline,
            outputs,
            dump: self.dump.clone(),
            worst_count: self.worst_count,
            csv: self.csv.clone(),
            markdown: self.markdown.clone(),
            worst: self.worst.clone(),
        })
    }
}
