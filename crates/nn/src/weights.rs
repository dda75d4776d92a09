//! Weight files: safetensors of named f32 tensors plus one JSON record under
//! the metadata key "pgrf" that says which network it is (architecture and its
//! configuration), what noise it was trained on, how training went, and for
//! the flow model the searched t2. Everything a later command needs to use
//! the file travels with it, so `pgrf enhance` needs no flags about the model.
//!
//! The file format only: building the network a file describes is
//! [`crate::model::load`]'s, the networks are [`crate::arch`]'s.

use crate::arch::Architecture;
use crate::error::{NnError, Result};
use crate::named::NamedTensor;
use pgrf_core::record::{self, RecordError};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// Value of `format` in every weight file.
const FORMAT: &str = "pgrf-weights";
/// Version of the record this pgrf writes; newer files are refused.
const VERSION: u32 = 1;

/// Which noise the network learned to remove.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct NoiseSource {
    /// Camera profile name or path.
    pub profile: Option<String>,
    /// Identity of the calibration file (camera, ISO, file name), when one was used.
    pub calibration: Option<String>,
    /// Noise model (pg, eld or pgrf in the record).
    pub model: pgrf_noise::ModelKind,
    /// Fixed ISO, or None for ELD-sampled parameters.
    pub iso: Option<u32>,
    /// The ISO range the gain was drawn from (first profile of a mix), when
    /// training narrowed it; absent in files written before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub iso_range: Option<[u32; 2]>,
    /// Exposure-ratio range the pairs were drawn from.
    pub ratio: [f32; 2],
    /// The captures carried no dark-level offset (`calibrated_dark_level`):
    /// the network expects calibrated input. Absent (false) in older files.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub calibrated_dark_level: bool,
}

/// How training went, for people choosing between files.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct TrainingSummary {
    /// Optimisation steps completed.
    pub steps: u64,
    /// Crops per step.
    pub batch: usize,
    /// Side of the square packed training crops, in packed pixels (the flow
    /// model's largest inference tile is derived from it).
    pub patch: usize,
    /// Seed of the run.
    pub seed: u64,
    /// Where the clean training images came from, in words.
    pub data: String,
    /// Loss of the last step (L1, on [0, 1] data); NaN (null in the
    /// record) for a run stopped before its first step. Files in which an
    /// older pgrf wrote null (a resumed run that had already finished) read
    /// as NaN too, so that they load.
    #[serde(deserialize_with = "nan_if_null")]
    pub final_loss: f32,
    /// PSNR (dB) on the held-out validation pairs at the end of training
    /// (of the moving average when the run kept one: the weights stored).
    pub val_psnr: Option<f32>,
    /// With a moving average (`ema`): the raw weights' PSNR on the same
    /// pairs, the average's measured gain being `val_psnr` minus this.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub val_psnr_raw: Option<f32>,
    /// Training seconds, summed over resumed runs.
    pub seconds: f64,
    /// Training crops per second of the last run.
    pub images_per_s: f64,
    /// The compute device, in words.
    pub device: String,
    /// The whole training configuration (files written before it was
    /// recorded have none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub config: Option<crate::TrainConfig>,
    /// The trained model this run started from (`init`), when it was a
    /// fine-tuning run: `steps` and `seconds` above count this run alone.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub started_from: Option<StartedFrom>,
}

/// A number that JSON may hold as null (serde_json writes NaN so): NaN.
fn nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> std::result::Result<f32, D::Error> {
    Ok(Option::<f32>::deserialize(d)?.unwrap_or(f32::NAN))
}

/// The weights a fine-tuning run started from, and what training they had
/// had, so a model's whole history (steps, machine time) can be added up.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct StartedFrom {
    /// The weight file's name.
    pub file: String,
    /// Steps that file had been trained for, its own history included.
    pub steps: u64,
    /// Training seconds behind that file, its own history included.
    pub seconds: f64,
}

impl StartedFrom {
    /// What a run starting from the weights of `meta` (read from the file
    /// `path`) records: that file's steps and seconds, and those of the
    /// model it started from in turn. A file not trained by `pgrf train`
    /// (imported weights) counts as no steps.
    pub fn of(path: &Path, meta: &WeightMeta) -> StartedFrom {
        let t = meta.training.as_ref();
        let earlier = t.and_then(|t| t.started_from.as_ref());
        StartedFrom {
            file: path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| path.display().to_string()),
            steps: t.map_or(0, |t| t.steps) + earlier.map_or(0, |e| e.steps),
            seconds: t.map_or(0.0, |t| t.seconds) + earlier.map_or(0.0, |e| e.seconds),
        }
    }
}

/// Where a network imported from another framework's file came from
/// (`pgrf import-weights`), and the input convention its authors used,
/// so that whoever runs it knows what pgrf applies and what it cannot.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct ImportedFrom {
    /// The source file's name.
    pub file: String,
    /// SHA-256 of the source file, hex.
    pub sha256: String,
    /// The container, in words ("PyTorch zip checkpoint", "safetensors").
    pub container: String,
    /// The nesting the tensors were found under ("netG.", "module.", or
    /// empty for a plain state dict).
    pub nesting: String,
    /// Other nestings the file holds the network under (LED's
    /// `params_ema`), not imported.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub also_under: Vec<String>,
    /// The repository the weights are from (`--from`), when given.
    pub repository: Option<String>,
    /// That repository's input and output convention, and what pgrf does
    /// differently at inference, in words.
    pub convention: Option<String>,
}

/// The record stored in every weight file, as JSON under the safetensors
/// metadata key "pgrf".
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct WeightMeta {
    /// Always "pgrf-weights" (pgrf's calibration files share the container).
    pub format: String,
    /// Version of the record; files newer than this pgrf reads are refused.
    pub version: u32,
    /// The network (`arch` and `config` keys at the top level).
    #[serde(flatten)]
    pub arch: Architecture,
    /// The noise the network learned to remove.
    pub noise: NoiseSource,
    /// How training went; None for networks not trained by `pgrf train`.
    pub training: Option<TrainingSummary>,
    /// Second time of the two-stage sampler (flow model), from the sampling
    /// search; None until searched.
    pub t2: Option<f32>,
    /// Set for a network imported from another framework's file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub imported: Option<ImportedFrom>,
}

impl WeightMeta {
    /// The record of a network of `arch` trained on `noise`, of the current
    /// format and version, with no training summary and no searched t2.
    pub fn new(arch: Architecture, noise: NoiseSource) -> WeightMeta {
        WeightMeta {
            format: FORMAT.into(),
            version: VERSION,
            arch,
            noise,
            training: None,
            t2: None,
            imported: None,
        }
    }
}

fn err(path: &Path, reason: impl std::fmt::Display) -> NnError {
    NnError::BadFile {
        path: path.to_path_buf(),
        reason: reason.to_string(),
    }
}

/// Config keys added after files were first written, with the value that
/// reproduces the older network: burn's `Config` has no serde defaults, so
/// they are filled in before the record is read.
fn fill_defaults(value: &mut serde_json::Value) {
    if matches!(
        value.get("arch").and_then(|a| a.as_str()),
        Some("sid-unet") | Some("sr3")
    ) {
        if let Some(c) = value.get_mut("config").and_then(|c| c.as_object_mut()) {
            c.entry("residual")
                .or_insert(serde_json::Value::Bool(false));
            c.entry("conditioning")
                .or_insert(serde_json::Value::String("none".into()));
            c.entry("keep_below_black")
                .or_insert(serde_json::Value::Bool(false));
        }
    }
}

/// Serialise named tensors and the record to safetensors bytes.
pub(crate) fn encode(
    tensors: &BTreeMap<String, NamedTensor>,
    meta: &WeightMeta,
) -> Result<Vec<u8>> {
    let text = serde_json::to_string(meta).map_err(|e| NnError::Invalid(e.to_string()))?;
    record::encode(
        tensors
            .iter()
            .map(|(n, t)| (n.as_str(), &t.shape[..], &t.values[..])),
        &text,
    )
    .map_err(|e| NnError::Invalid(e.to_string()))
}

/// Write `module`'s parameters and `meta` atomically (tests write bare
/// networks; commands save a [`crate::Net`]).
#[cfg(test)]
pub(crate) fn save<B: burn::tensor::backend::Backend, M: burn::module::Module<B>>(
    path: &Path,
    module: &M,
    meta: &WeightMeta,
) -> Result<()> {
    let bytes = encode(&crate::named::collect::<B, M>(module), meta)?;
    Ok(pgrf_core::write_atomic(path, &bytes)?)
}

/// Parse weight-file bytes into the record (checked to be a weight file
/// this pgrf reads) and the named tensors (checked to be finite); `path`
/// names them in errors. What [`read`] and [`load`](crate::model::load) do with a file's
/// bytes, without building a network: the byte-level entry point for
/// weights built into the binary and for fuzzing.
pub fn from_bytes(
    bytes: &[u8],
    path: &Path,
) -> Result<(WeightMeta, BTreeMap<String, NamedTensor>)> {
    let meta = decode_meta(path, bytes)?;
    let rec = record::decode(bytes).map_err(|e| err(path, e))?;
    for (name, t) in &rec.tensors {
        if let Some(bad) = t.values.iter().position(|v| !v.is_finite()) {
            return Err(err(
                path,
                format!("tensor {name} holds a non-finite value at index {bad}"),
            ));
        }
    }
    Ok((meta, rec.tensors))
}

/// The record of weight-file bytes, checked to be a weight file this pgrf reads.
fn decode_meta(path: &Path, bytes: &[u8]) -> Result<WeightMeta> {
    let text = record::read_meta(bytes).map_err(|e| match e {
        RecordError::NoRecord => err(
            path,
            "no pgrf record in the metadata (not a pgrf weight file)",
        ),
        e => err(path, e),
    })?;
    let mut value: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| err(path, format!("bad metadata: {e}")))?;
    fill_defaults(&mut value);
    if value.get("format").and_then(|f| f.as_str()) != Some(FORMAT) {
        return Err(err(
            path,
            "this is a pgrf file but not a weight file (a calibration or truth map?)",
        ));
    }
    let meta: WeightMeta =
        serde_json::from_value(value).map_err(|e| err(path, format!("bad metadata: {e}")))?;
    if meta.version > VERSION {
        return Err(err(
            path,
            format!(
                "weight file version {} is newer than this pgrf reads ({VERSION})",
                meta.version
            ),
        ));
    }
    Ok(meta)
}

/// Read a weight file's record (checked to be a weight file this pgrf
/// reads) without building the network.
pub fn read_meta(path: &Path) -> Result<WeightMeta> {
    Ok(read(path)?.0)
}

/// The record of `path` when its network can start a run of `arch` (what a
/// fine-tuning run's `--init` must name: the same network, or the same one
/// without the noise conditioning, [`Architecture::can_start_from`]), else
/// one line saying what it holds instead.
pub fn require_arch(path: &Path, arch: &Architecture) -> Result<WeightMeta> {
    let meta = read_meta(path)?;
    check_arch(path, &meta, arch)?;
    Ok(meta)
}

/// [`require_arch`]'s comparison, for a record already read.
pub(crate) fn check_arch(path: &Path, meta: &WeightMeta, arch: &Architecture) -> Result<()> {
    if !arch.can_start_from(&meta.arch) {
        return Err(NnError::WrongArchitecture {
            path: path.to_path_buf(),
            message: format!(
                "--init {}: holds {}, not the {} this configuration trains{}",
                path.display(),
                meta.arch.describe(),
                arch.describe(),
                if arch.conditioning().extra_channels() > 0 {
                    " (or the same network without its noise conditioning)"
                } else {
                    ""
                }
            ),
        });
    }
    Ok(())
}

/// Read a weight file: its record and its named tensors, checked to be
/// finite (a damaged file is refused with the tensor's name).
pub fn read(path: &Path) -> Result<(WeightMeta, BTreeMap<String, NamedTensor>)> {
    from_bytes(&read_bytes(path)?, path)
}

/// A weight file's bytes, with the path in the error.
pub(crate) fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| err(path, e))
}

/// Rewrite only the record of an existing weight file (e.g. the searched t2),
/// atomically, keeping the tensors bit for bit.
pub fn update_meta(path: &Path, f: impl FnOnce(&mut WeightMeta)) -> Result<WeightMeta> {
    let (mut meta, tensors) = read(path)?;
    f(&mut meta);
    let bytes = encode(&tensors, &meta)?;
    pgrf_core::write_atomic(path, &bytes)?;
    Ok(meta)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arch::{SidUnetConfig, Sr3Config};
    use crate::backend::Cpu;
    use crate::model::{load_denoiser, load_flow};
    use burn::tensor::{Distribution, Tensor};

    fn tmp(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("pgrf-nn-weights-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d.join(name)
    }

    #[test]
    fn records_from_before_the_residual_option_read_as_plain_sid() {
        let mut v = serde_json::json!({
            "format": FORMAT, "version": 1, "arch": "sid-unet",
            "config": {"width": 8, "in_channels": 4, "out_channels": 4},
            "noise": {"profile": null, "calibration": null, "model": "pgrf", "iso": null, "ratio": [100.0, 300.0]},
            "training": null, "t2": null
        });
        fill_defaults(&mut v);
        let m: WeightMeta = serde_json::from_value(v).unwrap();
        match m.arch {
            Architecture::SidUnet(c) => assert!(!c.residual && c.width == 8),
            _ => panic!("wrong architecture"),
        }
    }

    fn noise() -> NoiseSource {
        NoiseSource {
            profile: Some("sony-a7s2".into()),
            calibration: None,
            model: pgrf_noise::ModelKind::Pgrf,
            iso: None,
            iso_range: None,
            ratio: [100.0, 300.0],
            calibrated_dark_level: false,
        }
    }

    #[test]
    fn save_load_gives_identical_outputs_and_keeps_the_record() {
        let device = Default::default();
        let cfg = SidUnetConfig::new().with_width(4);
        let net = cfg.init::<Cpu>(&device);
        let p = tmp("spc.safetensors");
        let mut meta = WeightMeta::new(Architecture::SidUnet(cfg), noise());
        let config = crate::TrainConfig {
            steps: 12,
            width: Some(4),
            ..Default::default()
        };
        meta.training = Some(TrainingSummary {
            steps: 12,
            final_loss: 0.25,
            config: Some(config.clone()),
            ..Default::default()
        });
        save::<Cpu, _>(&p, &net, &meta).unwrap();
        let (back, m) = load_denoiser::<Cpu>(&p, &device).unwrap();
        assert_eq!(m.training.as_ref().unwrap().steps, 12);
        assert_eq!(m.training.as_ref().unwrap().config, Some(config));
        assert_eq!(m.noise, noise());
        let x = Tensor::<Cpu, 4>::random([1, 4, 20, 36], Distribution::Default, &device);
        let a: Vec<f32> = net.forward(x.clone()).into_data().to_vec().unwrap();
        let b: Vec<f32> = back.forward(x).into_data().to_vec().unwrap();
        assert_eq!(a, b);
    }

    #[test]
    fn the_wrong_kind_and_a_wrong_config_are_refused() {
        let device = Default::default();
        let cfg = Sr3Config::new()
            .with_inner_channels(8)
            .with_channel_mults(vec![1, 2])
            .with_res_blocks(1)
            .with_attn_levels(vec![1])
            .with_norm_groups(4);
        let net = cfg.init::<Cpu>(&device).unwrap();
        let p = tmp("flow.safetensors");
        save::<Cpu, _>(&p, &net, &WeightMeta::new(Architecture::Sr3(cfg), noise())).unwrap();
        let e = load_denoiser::<Cpu>(&p, &device).unwrap_err().to_string();
        assert!(e.contains("not spc"), "{e}");
        assert!(load_flow::<Cpu>(&p, &device).is_ok());
        // The record says one width, the tensors are of another network.
        let bytes = std::fs::read(&p).unwrap();
        let (_, tensors) = from_bytes(&bytes, &p).unwrap();
        let wrong = WeightMeta::new(
            Architecture::Sr3(Sr3Config::new().with_inner_channels(16).with_norm_groups(4)),
            noise(),
        );
        let q = tmp("wrong.safetensors");
        std::fs::write(&q, encode(&tensors, &wrong).unwrap()).unwrap();
        let e = load_flow::<Cpu>(&q, &device).unwrap_err().to_string();
        assert!(e.contains("weights do not fit"), "{e}");
    }

    #[test]
    fn t2_is_rewritten_in_place_and_other_files_are_refused() {
        let device = Default::default();
        let cfg = SidUnetConfig::new().with_width(2);
        let p = tmp("t2.safetensors");
        save::<Cpu, _>(
            &p,
            &cfg.init::<Cpu>(&device),
            &WeightMeta::new(Architecture::SidUnet(cfg), noise()),
        )
        .unwrap();
        let before = read(&p).unwrap().1;
        update_meta(&p, |m| m.t2 = Some(0.3)).unwrap();
        let (m, after) = read(&p).unwrap();
        assert_eq!(m.t2, Some(0.3));
        assert_eq!(before, after);
        let junk = tmp("junk.safetensors");
        std::fs::write(&junk, b"not a weight file at all").unwrap();
        assert!(read(&junk)
            .unwrap_err()
            .to_string()
            .contains("not a safetensors"));
    }
}
