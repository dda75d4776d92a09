//! The synthetic protocol: real clean photographs made dark and noisy in
//! memory, at a grid of conditions, so a model can be judged on real scene
//! content without a paired low-light dataset.
//!
//! For every clean file (a RAW pgrf decodes, or a JPEG/PNG/TIFF photo) and
//! every condition (ISO x exposure ratio, default
//! [`DEFAULT_ISOS`] x [`DEFAULT_RATIOS`]):
//!
//! 1. the clean reference is the file packed R, G1, B, G2, normalised by its
//!    own black and white levels and clipped to [0, 1] (a photo is first
//!    downscaled 2x and unprocessed into the Sony A7S2's camera space,
//!    [`pgrf_scenes::unprocess`]);
//! 2. the dark capture is synthesised from it by [`PairSpec::synthesize`]
//!    with the camera profile's parameters at that ISO and the fixed ratio:
//!    the reference, taken as the profile camera's normalised signal, is
//!    divided by the ratio, put through the noise model and multiplied back;
//! 3. the network input is that capture minus its dark-level offset and
//!    clamped to [0, 1] (the "noisy input" column too): the camera is taken
//!    as calibrated, so the profile's black-level error at the ISO (which
//!    the capture carries, ELD's per-ISO bias) is known and subtracted, as
//!    `pgrf enhance --calib` subtracts a calibration's fixed pattern (bias
//!    frames' mean minus the file's black level) from a real photo, and as
//!    the VST+BM3D peer is given the true offset ([`Synthetic::calibrated_input`]);
//! 4. PSNR/SSIM under ELD's measurement, by default without illuminance
//!    correction (the exposure is known exactly), and the colour cast of
//!    [`crate::cast`].
//!
//! Seeds: the capture of file `name` at (ISO, ratio) is drawn with seed
//! [`capture_seed`]`(seed, name, condition)` =
//! `mix64(mix64(mix64(seed ^ fnv1a64(name)) ^ ISO) ^ bits(ratio as f32))`
//! (`mix64` is SplitMix64's finaliser, [`pgrf_core::seed::mix64`];
//! `fnv1a64` the 64-bit FNV-1a hash of the file name's UTF-8 bytes, without
//! its folder). It depends on the file's name, not on its place in the list,
//! so adding files does not change the others' noise, and the same command
//! gives byte-identical numbers. Two clean files with the same name are
//! refused.

use super::run::{case_key, run_cases, Case, Outcome, RunOptions, Synthesis};
use super::table::{NoiseRecord, Row};
use super::{err, DatasetError, DatasetKind, LoadedPair, Result};
use crate::method::CaseNoise;
use crate::method::MethodUnderTest;
use ndarray::{Array3, ArrayView3};
use pgrf_core::seed::mix64;
use pgrf_core::Progress;
use pgrf_noise::pair::{PairSpec, RatioSpec};
use pgrf_noise::{CameraProfile, ModelKind};
use pgrf_raw::{decode_file, pack_normalized, LevelOverrides, RawFrame};
use pgrf_scenes::unprocess::{unprocess, CameraSpace};
use std::path::{Path, PathBuf};

/// The default ISOs of the grid.
pub const DEFAULT_ISOS: [u32; 4] = [800, 1600, 3200, 6400];
/// The default exposure ratios of the grid.
pub const DEFAULT_RATIOS: [f32; 4] = [50.0, 100.0, 200.0, 300.0];
/// Photo extensions (lower case) read as photos and unprocessed.
pub const PHOTO_EXTENSIONS: [&str; 5] = ["jpg", "jpeg", "png", "tif", "tiff"];

/// One capture condition.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Condition {
    /// ISO: the noise parameters are the profile's at this ISO.
    pub iso: u32,
    /// Exposure ratio: the capture gets 1/ratio of the reference's light.
    pub ratio: f32,
}

impl Condition {
    /// "ISO 1600 x100".
    pub fn label(&self) -> String {
        format!("ISO {} x{}", self.iso, self.ratio)
    }
}

fn split(text: &str, flag: &str) -> Result<Vec<String>> {
    let items: Vec<String> = text.split(',').map(|s| s.trim().to_string()).collect();
    if items.iter().any(String::is_empty) {
        return err(format!(
            "{flag} {text:?}: expected a comma-separated list of numbers"
        ));
    }
    Ok(items)
}

/// Parse `--iso`: comma-separated positive whole numbers, no duplicates.
pub fn parse_isos(text: &str) -> Result<Vec<u32>> {
    let mut out: Vec<u32> = Vec::new();
    for item in split(text, "--iso")? {
        let v = match item.parse::<u32>() {
            Ok(v) if v > 0 => v,
            _ => return err(format!("--iso {item:?}: not a positive whole number")),
        };
        if out.contains(&v) {
            return err(format!("--iso {text:?}: ISO {v} is given twice"));
        }
        out.push(v);
    }
    Ok(out)
}

/// Parse `--ratio`: comma-separated finite numbers >= 1, no two in the same
/// table row (rows are the ratios rounded to whole numbers).
pub fn parse_ratios(text: &str) -> Result<Vec<f32>> {
    let mut out: Vec<f32> = Vec::new();
    for item in split(text, "--ratio")? {
        let v = match item.parse::<f32>() {
            Ok(v) => pgrf_noise::pair::ratio_in_range("--ratio", v)
                .map_err(|e| DatasetError(e.to_string()))?,
            Err(_) => {
                return err(format!(
                    "--ratio {item:?}: not a number (the exposure ratio, from 1 to 10000)"
                ))
            }
        };
        if let Some(o) = out.iter().find(|o| o.round() == v.round()) {
            return err(format!(
                "--ratio {text:?}: {o} and {v} are the same table row x{}",
                v.round()
            ));
        }
        out.push(v);
    }
    Ok(out)
}

/// Every ISO with every ratio, ISO-major (the table's row order).
pub fn grid(isos: &[u32], ratios: &[f32]) -> Vec<Condition> {
    isos.iter()
        .flat_map(|&iso| ratios.iter().map(move |&ratio| Condition { iso, ratio }))
        .collect()
}

/// 64-bit FNV-1a of `bytes`: a hash fixed by its definition, stable across
/// platforms and Rust versions (unlike `std`'s hasher).
fn fnv1a64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// The noise seed of the capture of clean file `name` (its file name,
/// without folder) at `c`, under the user's `seed`:
/// `mix64(mix64(mix64(seed ^ fnv1a64(name)) ^ iso) ^ bits(ratio))`.
pub fn capture_seed(seed: u64, name: &str, c: &Condition) -> u64 {
    mix64(mix64(mix64(seed ^ fnv1a64(name.as_bytes())) ^ c.iso as u64) ^ c.ratio.to_bits() as u64)
}

/// One clean file of the protocol.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Its file name: the id in tables and the seed's input.
    pub id: String,
    /// The file.
    pub path: PathBuf,
    /// A photo to unprocess (by extension), not a RAW file.
    pub photo: bool,
}

impl Image {
    fn of(path: &Path) -> Image {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        Image {
            id: path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| path.display().to_string()),
            path: path.to_path_buf(),
            photo: PHOTO_EXTENSIONS.contains(&ext.as_str()),
        }
    }

    /// Decode it: a RAW file with `levels` overriding its own, or a photo
    /// downscaled 2x and unprocessed into the Sony A7S2's camera space.
    pub fn load(&self, levels: &LevelOverrides) -> Result<RawFrame> {
        let e = |e: pgrf_raw::RawError| DatasetError(e.to_string());
        if !self.photo {
            // A monochrome frame is scored on its four packed sub-lattices,
            // as enhance restores it.
            return decode_file(&self.path, levels).map_err(e);
        }
        let photo = pgrf_scenes::photo::read_photo(&self.path)
            .and_then(|p| p.downscale(2))
            .map_err(|x| DatasetError(x.to_string()))?;
        unprocess(&photo, &CameraSpace::sony_a7s2(), 1.0)
            .map_err(|x| DatasetError(format!("{}: {x}", self.path.display())))
    }
}

/// The clean files of `roots`, in the order given: a file is itself, a
/// folder its files sorted by name (hidden ones skipped). Every root must
/// exist; file names must be unique (they seed the noise).
pub fn walk(roots: &[PathBuf]) -> Result<Vec<Image>> {
    if roots.is_empty() {
        return err("no clean files: give --root FILE or FOLDER");
    }
    let mut out: Vec<Image> = Vec::new();
    for root in roots {
        let files = if root.is_dir() {
            pgrf_raw::files::list_files(root).map_err(|e| DatasetError(e.to_string()))?
        } else if root.is_file() {
            vec![root.clone()]
        } else {
            return err(format!("{}: no such file or folder", root.display()));
        };
        for f in files {
            let img = Image::of(&f);
            if let Some(o) = out.iter().find(|o| o.id == img.id) {
                return err(format!(
                    "{} and {} have the same file name: the synthetic protocol seeds each \
                     capture from the name, so names must be unique",
                    o.path.display(),
                    f.display()
                ));
            }
            out.push(img);
        }
    }
    Ok(out)
}

/// The recipe of a synthetic run: noise model, conditions and seed.
#[derive(Clone, Debug)]
pub struct Synthetic {
    /// The conditions, in table order.
    pub conditions: Vec<Condition>,
    /// The user's seed, mixed into every capture's ([`capture_seed`]).
    pub seed: u64,
    profile: String,
    kind: ModelKind,
    /// One pair recipe per condition (ISO and ratio fixed).
    specs: Vec<PairSpec>,
    /// Hand the methods the capture with its dark-level offset kept, as an
    /// uncalibrated camera does ([`Synthetic::input`]).
    pub uncalibrated: bool,
    /// Tell noise-aware methods the blind estimate of each capture's noise
    /// instead of its true parameters ([`Synthetic::case_noise`]).
    pub blind_noise: bool,
}

impl Synthetic {
    /// `kind` noise on camera profile `profile` (a built-in name, a JSON
    /// file, `darktable:` a camera of `darktable`'s file or darktable's
    /// install) at `conditions`; every ISO must be one the profile has
    /// parameters for, every ratio >= 1, and the list not empty.
    pub fn new(
        profile: &str,
        kind: ModelKind,
        conditions: Vec<Condition>,
        seed: u64,
        darktable: Option<&Path>,
    ) -> Result<Synthetic> {
        if conditions.is_empty() {
            return err("no conditions: give at least one --iso and one --ratio");
        }
        let camera =
            CameraProfile::load(profile, darktable).map_err(|e| DatasetError(e.to_string()))?;
        let mut specs = Vec::new();
        for c in &conditions {
            pgrf_noise::pair::ratio_in_range("ratio", c.ratio)
                .map_err(|e| DatasetError(e.to_string()))?;
            camera
                .params_at_iso(c.iso)
                .map_err(|e| DatasetError(format!("--iso {}: {e}", c.iso)))?;
            let mut spec = PairSpec::new(camera.clone(), kind);
            spec.iso = Some(c.iso);
            spec.ratio = RatioSpec::Fixed(c.ratio);
            specs.push(spec);
        }
        Ok(Synthetic {
            conditions,
            seed,
            profile: profile.to_string(),
            kind,
            specs,
            uncalibrated: false,
            blind_noise: false,
        })
    }

    /// The network input for clean packed `clean` (file `name`, planes on
    /// sensor rows `plane_rows`) at condition number `k`: the amplified
    /// capture, calibrated and clamped ([`Synthetic::calibrated_input`]),
    /// and the seed it was drawn with.
    pub fn capture(
        &self,
        clean: ArrayView3<f32>,
        plane_rows: [usize; 4],
        name: &str,
        k: usize,
    ) -> Result<(Array3<f32>, u64)> {
        let (pair, seed) = self.synthesize(clean, plane_rows, name, k)?;
        Ok((self.input(&pair), seed))
    }

    /// What the methods are handed: the calibrated input
    /// ([`Synthetic::calibrated_input`]), or with `uncalibrated` the
    /// amplified capture as the camera wrote it, dark-level offset kept,
    /// clamped to [0, 1]: what `pgrf enhance` without `--calib` sees, and
    /// what a network must not lift the black of (issue 36, item 3).
    pub fn input(&self, pair: &pgrf_noise::pair::Pair) -> Array3<f32> {
        if self.uncalibrated {
            pair.noisy.mapv(|v| v.min(1.0))
        } else {
            self.calibrated_input(pair)
        }
    }

    /// What a calibrated camera hands the denoiser: the amplified capture
    /// minus its dark-level offset (the capture's per-plane bias in DN,
    /// times the ratio, over the DN range: the `offset` of the noise
    /// record), clamped to [0, 1]. A calibration (bias frames) measures that
    /// offset; without it a network must guess the camera's black-level
    /// error, which at x100-x200 shifts dark areas by several percent of
    /// full scale and tints them.
    pub fn calibrated_input(&self, pair: &pgrf_noise::pair::Pair) -> Array3<f32> {
        self.minus_offsets(pair, |v| v.min(1.0))
    }

    /// Each plane of the amplified capture minus its dark-level offset
    /// ([`Synthetic::offsets`]), then `f`.
    fn minus_offsets(&self, pair: &pgrf_noise::pair::Pair, f: impl Fn(f32) -> f32) -> Array3<f32> {
        let mut out = pair.noisy.clone();
        let offsets = self.offsets(&pair.params, pair.ratio);
        for (mut plane, off) in out.outer_iter_mut().zip(offsets) {
            let off = off as f32;
            plane.mapv_inplace(|v| f(v - off));
        }
        out
    }

    /// The read noise (DN) of a capture drawn with `params`: Gaussian in the
    /// pgrf and P-G models, Tukey-lambda in ELD's (its scale stands for the
    /// spread).
    fn read_sigma(&self, params: &pgrf_noise::CaptureParams) -> f64 {
        match self.kind {
            ModelKind::Eld => params.sigma_tukey,
            _ => params.sigma_gauss,
        }
    }

    /// The dark-level offset of an amplified, normalised capture drawn with
    /// `params` at `ratio`, per plane: ratio x bias (DN) / DN range.
    fn offsets(&self, params: &pgrf_noise::CaptureParams, ratio: f32) -> [f64; 4] {
        let scale = ratio as f64 / self.specs[0].dn_range();
        params.bias.map(|b| b * scale)
    }

    /// What a noise-aware method is told of `pair`: its true parameters,
    /// which a calibrated camera measures and which `find_noise` reads,
    /// uncalibrated, from the camera's profile at its ISO (the profile the
    /// capture was drawn from); with `blind_noise`, what
    /// [`pgrf_noise::estimate::fit`] finds in the capture the method gets
    /// (before amplification and clamping), as `pgrf enhance` does for a
    /// camera it has no profile of. Also the truth, for the record.
    pub fn case_noise(&self, pair: &pgrf_noise::pair::Pair) -> Result<(CaseNoise, NoiseRecord)> {
        let params = &pair.params;
        let read = self.read_sigma(params);
        let range = self.specs[0].dn_range();
        let record = |told: &CaseNoise| NoiseRecord {
            told_k: told.k,
            told_read: told.read,
            true_k: params.k,
            true_read: read,
        };
        if !self.blind_noise {
            let told = CaseNoise {
                k: params.k,
                read,
                row: params.sigma_row,
                range,
                source: if self.uncalibrated {
                    "the simulated camera's profile at its ISO".into()
                } else {
                    "the simulated camera's calibration".into()
                },
            };
            let r = record(&told);
            return Ok((told, r));
        }
        // The capture as the method gets it, before amplification and
        // clamping.
        let capture = if self.uncalibrated {
            pair.noisy.mapv(|v| v / pair.ratio)
        } else {
            self.minus_offsets(pair, |v| v / pair.ratio)
        };
        let fit = pgrf_noise::estimate::fit(capture.view())
            .map_err(|e| DatasetError(format!("blind noise estimate: {e}")))?;
        let (k, read_est) = fit.in_dn(range);
        let told = CaseNoise {
            k,
            read: read_est,
            row: 0.0,
            range,
            source: format!(
                "blind estimate of the capture ({} blocks; true K {:.4}, read {:.2})",
                fit.blocks, params.k, read
            ),
        };
        let r = record(&told);
        Ok((told, r))
    }

    /// The whole synthesised pair behind [`Synthetic::capture`], and its seed.
    fn synthesize(
        &self,
        clean: ArrayView3<f32>,
        plane_rows: [usize; 4],
        name: &str,
        k: usize,
    ) -> Result<(pgrf_noise::pair::Pair, u64)> {
        let c = &self.conditions[k];
        let seed = capture_seed(self.seed, name, c);
        let pair = self.specs[k]
            .synthesize(clean, plane_rows, seed)
            .map_err(|e| DatasetError(format!("{name} {}: {e}", c.label())))?;
        Ok((pair, seed))
    }

    /// The true noise of a capture drawn with `params`, as the `--dump`
    /// sidecar records it: the parameters in DN of the profile's scale, and
    /// the Poisson-Gaussian approximation of the amplified, normalised
    /// capture y (what a variance-stabilising transform needs):
    /// E[y] = x + offset, Var[y] = alpha * x + sigma^2.
    fn noise_record(&self, params: &pgrf_noise::CaptureParams, ratio: f32) -> serde_json::Value {
        let dn = self.specs[0].dn_range();
        let r = ratio as f64;
        // Read, row noise and 1-DN quantisation.
        let read = self.read_sigma(params);
        let var_dn = read * read + params.sigma_row * params.sigma_row + 1.0 / 12.0;
        serde_json::json!({
            "profile": self.profile,
            "model": self.kind.to_string(),
            "k_dn_per_electron": params.k,
            "sigma_read_dn": read,
            "sigma_row_dn": params.sigma_row,
            "quant_step_dn": 1.0,
            "bias_dn": params.bias,
            "dn_range": dn,
            "alpha": r * params.k / dn,
            "sigma": r * var_dn.sqrt() / dn,
            "offset": self.offsets(params, ratio),
        })
    }

    /// One line: conditions, noise model and seeds.
    pub fn describe(&self) -> String {
        let isos: Vec<String> = dedup(self.conditions.iter().map(|c| c.iso.to_string()));
        let ratios: Vec<String> = dedup(self.conditions.iter().map(|c| c.ratio.to_string()));
        format!(
            "ISO {} x ratio {} ({} conditions), noise model {} of profile {} at each ISO; \
             {}; capture seed = mix64(mix64(mix64({} ^ fnv1a64(file name)) ^ ISO) ^ f32 bits of ratio)",
            isos.join(","),
            ratios.join(","),
            self.conditions.len(),
            self.kind,
            self.profile,
            if self.uncalibrated {
                "uncalibrated (dark-level offset kept)"
            } else {
                "calibrated (dark-level offset subtracted)"
            },
            self.seed
        ) + if self.blind_noise {
            "; noise-aware methods are told the blind estimate of each capture's noise"
        } else {
            ""
        }
    }
}

fn dedup(items: impl Iterator<Item = String>) -> Vec<String> {
    let mut v: Vec<String> = Vec::new();
    for i in items {
        if !v.contains(&i) {
            v.push(i);
        }
    }
    v
}

/// The case of image `img` (decoded as `frame`, packed `clean`) at
/// condition number `ci`: its capture synthesised and handed over as the
/// methods get it, the noise they are told, the row's identity, and (with
/// `dump`) what the `--dump` sidecar records.
fn synthetic_case(
    synth: &Synthetic,
    img: &Image,
    frame: &RawFrame,
    clean: &Array3<f32>,
    ci: usize,
    dump: bool,
) -> Result<Case> {
    let c = synth.conditions[ci];
    let plane_rows = frame.cfa.offsets().map(|(r, _)| r);
    let (pair, seed) = synth.synthesize(clean.view(), plane_rows, &img.id, ci)?;
    let input = synth.input(&pair);
    let (noise, record) = synth.case_noise(&pair)?;
    let synthesis = dump.then(|| Synthesis {
        noise: synth.noise_record(&pair.params, c.ratio),
        capture: pair.noisy,
    });
    Ok(Case {
        pair: LoadedPair {
            reference_frame: frame.clone(),
            input,
            reference: clean.clone(),
            ratio: c.ratio,
            noise: Some(noise),
        },
        row: Row {
            protocol: DatasetKind::Synthetic.name().into(),
            id: img.id.clone(),
            group: c.ratio.round() as u32,
            ratio: c.ratio,
            noisy: String::new(),
            reference: img.path.display().to_string(),
            method: String::new(),
            psnr: f64::NAN,
            ssim: f64::NAN,
            gain: None,
            iso: Some(c.iso),
            seed: Some(seed),
            cast: None,
            black: None,
            noise: Some(record),
        },
        source: format!("{} ({})", img.path.display(), c.label()),
        title: format!("{} {}", img.id, c.label()),
        line: format!("{} {}", img.id, c.label()),
        key: case_key(&format!("{}_iso{}_x{}", img.id, c.iso, c.ratio)),
        synthesis,
    })
}

/// A note for each image whose colour cast was measured without a white
/// balance or a usable colour matrix (the first row of the image says).
fn cast_notes(images: &[Image], rows: &[Row]) -> Vec<String> {
    let mut notes = Vec::new();
    for img in images {
        let Some(c) = rows.iter().find(|r| r.id == img.id).and_then(|r| r.cast) else {
            continue;
        };
        let mut missing = Vec::new();
        if !c.white_balance {
            missing.push("no white balance (multipliers 1)");
        }
        if !c.matrix {
            missing.push("no usable colour matrix (camera RGB taken as linear sRGB)");
        }
        if !missing.is_empty() {
            notes.push(format!(
                "{}: cast measured with {}",
                img.id,
                missing.join(", ")
            ));
        }
    }
    notes
}

/// Run `methods` over every image of `images` at every condition of
/// `synth` (image-major; each file is decoded once). `progress` hears one
/// `advance` per capture. The colour cast is measured whatever
/// `opts.cast` says; `opts.crop` crops reference and capture before the
/// methods run.
pub fn run(
    images: &[Image],
    synth: &Synthetic,
    methods: &[&dyn MethodUnderTest],
    opts: &RunOptions,
    progress: &dyn Progress,
) -> Result<Outcome> {
    if images.is_empty() {
        return err("no clean files to evaluate");
    }
    let opts = RunOptions {
        cast: true,
        ..opts.clone()
    };
    let nc = synth.conditions.len();
    let mut cache: Option<(usize, RawFrame, Array3<f32>)> = None;
    let load = |k: usize| -> Result<Case> {
        let (i, ci) = (k / nc, k % nc);
        let img = &images[i];
        let (_, frame, clean) = match cache.take() {
            Some(e) if e.0 == i => cache.insert(e),
            _ => {
                let frame = img.load(&opts.levels)?;
                let clean = pack_normalized(&frame, true)
                    .map_err(|e| DatasetError(format!("{}: {e}", img.path.display())))?;
                cache.insert((i, frame, clean))
            }
        };
        synthetic_case(synth, img, frame, clean, ci, opts.dump.is_some())
    };
    let mut out = run_cases(
        images.len() * nc,
        "captures",
        load,
        methods,
        &opts,
        progress,
    )?;
    out.notes.extend(cast_notes(images, &out.rows));
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn condition_lists_parse_and_refuse() {
        assert_eq!(parse_isos("800, 1600,3200").unwrap(), vec![800, 1600, 3200]);
        assert_eq!(
            parse_ratios("50,100.5,300").unwrap(),
            vec![50.0, 100.5, 300.0]
        );
        for bad in ["", "800,", "0", "-800", "16o0", "800,800", "1.5"] {
            assert!(parse_isos(bad).is_err(), "{bad}");
        }
        for bad in [
            "",
            "0.5",
            "-100",
            "inf",
            "NaN",
            "100,100",
            "100,100.2",
            "x",
            "1e30",
            "10001",
        ] {
            assert!(parse_ratios(bad).is_err(), "{bad}");
        }
        let e = parse_ratios("100,100.2").unwrap_err().to_string();
        assert!(e.contains("x100"), "{e}");
        let g = grid(&[800, 1600], &[50.0, 100.0, 200.0]);
        assert_eq!(g.len(), 6);
        assert_eq!(
            g[0],
            Condition {
                iso: 800,
                ratio: 50.0
            }
        );
        assert_eq!(
            g[3],
            Condition {
                iso: 1600,
                ratio: 50.0
            }
        );
        assert_eq!(g[5].label(), "ISO 1600 x200");
        let d = grid(&DEFAULT_ISOS, &DEFAULT_RATIOS);
        assert_eq!(d.len(), 16);
    }

    #[test]
    fn isos_outside_the_profile_are_refused() {
        let c = |iso| vec![Condition { iso, ratio: 100.0 }];
        assert!(Synthetic::new("sony-a7s2", ModelKind::Pgrf, c(1600), 0, None).is_ok());
        let e = Synthetic::new("sony-a7s2", ModelKind::Pgrf, c(102400), 0, None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("102400") && e.contains("outside"), "{e}");
        assert!(Synthetic::new("sony-a7s2", ModelKind::Pgrf, vec![], 0, None).is_err());
        assert!(Synthetic::new("no-such-camera", ModelKind::Pgrf, c(1600), 0, None).is_err());
    }

    #[test]
    fn seeds_are_fixed_functions_of_name_and_condition() {
        // Pinned: a change of the formula changes every published number.
        let c = Condition {
            iso: 1600,
            ratio: 100.0,
        };
        assert_eq!(fnv1a64(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a64(b"a"), 0xaf63_dc4c_8601_ec8c);
        let want = mix64(mix64(mix64(fnv1a64(b"chart.dng")) ^ 1600) ^ 100f32.to_bits() as u64);
        assert_eq!(capture_seed(0, "chart.dng", &c), want);
        let others = [
            capture_seed(1, "chart.dng", &c),
            capture_seed(0, "chart2.dng", &c),
            capture_seed(0, "chart.dng", &Condition { iso: 3200, ..c }),
            capture_seed(0, "chart.dng", &Condition { ratio: 200.0, ..c }),
        ];
        for o in others {
            assert_ne!(o, want);
        }
    }

    #[test]
    fn the_calibrated_input_has_no_dark_level_offset() {
        // A flat grey far from the clamps, ISO 1600 x100: the capture
        // carries the A7S2's black-level error there (+2.43 DN, x100 over
        // the 16,383 - 512 DN range: +0.0153); the calibrated input is the
        // clean level on average. Noise sd ~0.045 over 16,384 samples: the
        // mean's standard error is ~0.00035, the tolerance 0.002 (~6 SE).
        let clean = Array3::from_elem((4, 64, 64), 0.3f32);
        let conds = grid(&[1600], &[100.0]);
        let s = Synthetic::new("sony-a7s2", ModelKind::Pgrf, conds, 3, None).unwrap();
        let (pair, _) = s
            .synthesize(clean.view(), [0, 0, 1, 1], "flat.dng", 0)
            .unwrap();
        let off = s.offsets(&pair.params, pair.ratio);
        assert!(off.iter().all(|o| (o - 0.0153).abs() < 0.0003), "{off:?}");
        let mean = |x: &Array3<f32>| x.iter().map(|&v| v as f64).sum::<f64>() / x.len() as f64;
        let raw = mean(&pair.noisy) - 0.3;
        let calibrated = mean(&s.calibrated_input(&pair)) - 0.3;
        assert!(
            (raw - off[0]).abs() < 0.002,
            "raw capture {raw} vs offset {}",
            off[0]
        );
        assert!(calibrated.abs() < 0.002, "calibrated input {calibrated}");
        // Uncalibrated (`--uncalibrated`): the methods get the offset.
        assert_eq!(s.input(&pair), s.calibrated_input(&pair));
        let uncal = Synthetic {
            uncalibrated: true,
            ..s.clone()
        };
        let kept = mean(&uncal.input(&pair)) - 0.3;
        assert!((kept - off[0]).abs() < 0.002, "uncalibrated input {kept}");
        assert!(uncal
            .describe()
            .contains("uncalibrated (dark-level offset kept)"));
        let record = s.noise_record(&pair.params, pair.ratio);
        assert_eq!(record["offset"][2].as_f64().unwrap(), off[2]);
    }

    #[test]
    fn captures_repeat_exactly_and_differ_between_conditions() {
        let clean = Array3::from_shape_fn((4, 32, 48), |(p, y, x)| {
            0.05 + 0.1 * p as f32 + 0.01 * ((x + 2 * y) % 17) as f32
        });
        let conds = grid(&[1600, 6400], &[100.0, 200.0]);
        let s = Synthetic::new("sony-a7s2", ModelKind::Pgrf, conds, 7, None).unwrap();
        let rows = [0, 0, 1, 1];
        let (a, sa) = s.capture(clean.view(), rows, "a.dng", 0).unwrap();
        let (b, sb) = s.capture(clean.view(), rows, "a.dng", 0).unwrap();
        assert_eq!(sa, sb);
        assert_eq!(a, b);
        // Clipped at white only: the values the camera recorded below black
        // stay negative (a network that reads them clamped clamps them).
        assert!(a.iter().all(|v| v.is_finite() && *v <= 1.0));
        assert!(a.iter().any(|v| *v < 0.0));
        // Noisy, but about the right brightness: the mean within 10 % of the
        // clean mean.
        let mean = |x: &Array3<f32>| x.iter().map(|&v| v as f64).sum::<f64>() / x.len() as f64;
        let rel = mean(&a) / mean(&clean) - 1.0;
        assert!(a != clean && rel.abs() < 0.1, "{rel}");
        // Another condition, or another name: other noise.
        for (k, name) in [(1, "a.dng"), (2, "a.dng"), (0, "b.dng")] {
            let (o, so) = s.capture(clean.view(), rows, name, k).unwrap();
            assert_ne!(so, sa);
            assert_ne!(o, a, "condition {k} {name}");
        }
        // Higher ISO at the same ratio: noisier.
        let err = |x: &Array3<f32>| {
            x.iter()
                .zip(clean.iter())
                .map(|(&o, &c)| ((o - c) as f64).powi(2))
                .sum::<f64>()
        };
        let (hi, _) = s.capture(clean.view(), rows, "a.dng", 2).unwrap();
        assert!(err(&hi) > err(&a), "{} vs {}", err(&hi), err(&a));
        // The same capture from a recipe with another seed base differs.
        let s2 =
            Synthetic::new("sony-a7s2", ModelKind::Pgrf, s.conditions.clone(), 8, None).unwrap();
        assert_ne!(s2.capture(clean.view(), rows, "a.dng", 0).unwrap().0, a);
    }

    #[test]
    fn walk_lists_files_and_folders_and_refuses_twins() {
        let d = std::env::temp_dir().join(format!("pgrf-synth-walk-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(d.join("sub")).unwrap();
        for n in ["b.dng", "a.JPG", ".hidden"] {
            std::fs::write(d.join("sub").join(n), b"x").unwrap();
        }
        std::fs::write(d.join("c.dng"), b"x").unwrap();
        let v = walk(&[d.join("c.dng"), d.join("sub")]).unwrap();
        let got: Vec<(&str, bool)> = v.iter().map(|i| (i.id.as_str(), i.photo)).collect();
        assert_eq!(
            got,
            vec![("c.dng", false), ("a.JPG", true), ("b.dng", false)]
        );
        let e = walk(&[d.join("nope.dng")]).unwrap_err().to_string();
        assert!(e.contains("nope.dng"), "{e}");
        assert!(walk(&[]).is_err());
        std::fs::write(d.join("b.dng"), b"x").unwrap();
        let e = walk(&[d.join("b.dng"), d.join("sub")])
            .unwrap_err()
            .to_string();
        assert!(e.contains("same file name"), "{e}");
        // A file that does not decode is an error naming it, not a panic.
        let e = v[2]
            .load(&LevelOverrides::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("b.dng"), "{e}");
        let e = v[1]
            .load(&LevelOverrides::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("a.JPG"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    /// A fresh folder holding the same 128 x 96 chart as one.dng and
    /// two.dng, and the chart.
    fn chart_folder(tag: &str) -> (std::path::PathBuf, pgrf_raw::RawFrame) {
        use pgrf_scenes::chart::{render_chart, ChartSpec};
        let d = std::env::temp_dir().join(format!("pgrf-synth-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        let frame = render_chart(&ChartSpec {
            width: 128,
            height: 96,
            ..Default::default()
        })
        .unwrap();
        for n in ["one.dng", "two.dng"] {
            pgrf_raw::write_dng(&frame, &d.join(n), &Default::default()).unwrap();
        }
        (d, frame)
    }

    /// The A7S2 at ISO 1600, x100 and x200.
    fn a7s2_x100_x200() -> Synthetic {
        Synthetic::new(
            "sony-a7s2",
            ModelKind::Pgrf,
            grid(&[1600], &[100.0, 200.0]),
            0,
            None,
        )
        .unwrap()
    }

    /// A 3x3 box blur per plane: a "denoiser" that must beat the input.
    fn box_blur(
        x: ArrayView3<f32>,
        _: &crate::method::CaseInfo,
    ) -> std::result::Result<Array3<f32>, crate::method::RestoreError> {
        let (c, h, w) = x.dim();
        Ok(Array3::from_shape_fn((c, h, w), |(p, i, j)| {
            let (mut s, mut n) = (0.0, 0.0);
            for y in i.saturating_sub(1)..(i + 2).min(h) {
                for xx in j.saturating_sub(1)..(j + 2).min(w) {
                    s += x[[p, y, xx]];
                    n += 1.0;
                }
            }
            s / n
        }))
    }

    fn worst_two() -> RunOptions {
        RunOptions {
            baseline: true,
            worst_count: 2,
            ..Default::default()
        }
    }

    #[test]
    fn a_run_covers_every_image_condition_and_method_reproducibly() {
        use crate::method::{CaseInfo, FnMethod, RestoreError};
        use pgrf_core::NoProgress;
        let (d, _) = chart_folder("run");
        let images = walk(std::slice::from_ref(&d)).unwrap();
        let synth = a7s2_x100_x200();
        let blur = FnMethod {
            name: "blur".into(),
            f: box_blur,
        };
        let methods: Vec<&dyn MethodUnderTest> = vec![&blur];
        let opts = worst_two();
        let a = run(&images, &synth, &methods, &opts, &NoProgress).unwrap();
        assert_eq!(a.rows.len(), 2 * 2 * 2);
        assert!(a.notes.is_empty(), "{:?}", a.notes);
        let order: Vec<(&str, f32, &str)> = a
            .rows
            .iter()
            .map(|r| (r.id.as_str(), r.ratio, r.method.as_str()))
            .collect();
        assert_eq!(
            order[..4],
            [
                ("one.dng", 100.0, "noisy input"),
                ("one.dng", 100.0, "blur"),
                ("one.dng", 200.0, "noisy input"),
                ("one.dng", 200.0, "blur"),
            ]
        );
        for pair in a.rows.chunks(2) {
            assert!(pair[1].psnr > pair[0].psnr + 1.0, "{pair:?}");
            assert!(pair.iter().all(|r| r.cast.is_some() && r.iso == Some(1600)));
            assert_eq!(pair[0].seed, pair[1].seed);
        }
        // Same chart, other name: other noise, other scores.
        assert_ne!(a.rows[0].psnr, a.rows[4].psnr);
        assert_eq!(a.worst.len(), 2);
        let b = run(&images, &synth, &methods, &opts, &NoProgress).unwrap();
        assert_eq!(a.rows, b.rows);
        // A failing method is an error naming the file and condition.
        let fail = FnMethod {
            name: "bad".into(),
            f: |_: ArrayView3<f32>,
                _: &CaseInfo|
             -> std::result::Result<Array3<f32>, RestoreError> {
                Err(RestoreError::method("out of memory"))
            },
        };
        let methods: Vec<&dyn MethodUnderTest> = vec![&fail];
        let e = run(&images, &synth, &methods, &opts, &NoProgress)
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("one.dng (ISO 1600 x100): model bad: out of memory"),
            "{e}"
        );
        std::fs::remove_dir_all(&d).unwrap();
    }

    /// A file without white balance or colour matrix: measured with the
    /// fallbacks, and a note says so.
    #[test]
    fn a_file_without_colour_data_is_measured_with_a_note() {
        let (d, frame) = chart_folder("plain");
        let mut plain = frame;
        plain.wb = None;
        plain.color_matrices.clear();
        let p = d.join("plain").join("plain.dng");
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        pgrf_raw::write_dng(&plain, &p, &Default::default()).unwrap();
        let methods: Vec<&dyn MethodUnderTest> = vec![];
        let o = run(
            &walk(&[p]).unwrap(),
            &a7s2_x100_x200(),
            &methods,
            &worst_two(),
            &pgrf_core::NoProgress,
        )
        .unwrap();
        assert_eq!(o.rows.len(), 2);
        let c = o.rows[0].cast.unwrap();
        assert!(!c.white_balance && !c.matrix, "{c:?}");
        assert_eq!(o.notes.len(), 1, "{:?}", o.notes);
        assert!(o.notes[0].starts_with("plain.dng: cast measured with no white balance"));
        std::fs::remove_dir_all(&d).unwrap();
    }
}
