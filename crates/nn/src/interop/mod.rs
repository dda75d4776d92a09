//! The field's published PyTorch models in, pgrf's models out.
//!
//! The best A7S2 low-light denoisers (SID, ELD, PMN, PNNP, LED) are public
//! checkpoints of one architecture pgrf has, the SID U-Net
//! (`UNetSeeInDark`). [`import_sid`] reads such a checkpoint (`.pth` or
//! safetensors, nested or not, DataParallel prefixes or not), checks every
//! tensor's name and shape against the architecture and returns a pgrf
//! weight file that records where it came from and its authors' input
//! convention. [`export`] writes a pgrf weight file for PyTorch: the SID
//! U-Net in `UNetSeeInDark`'s names (loadable with `load_state_dict(strict=
//! True)`), the SR3 network in pgrf's own names (`bench/sr3_reference.py`).

pub mod pickle_check;
mod pth_write;
pub use crate::arch::sid_names;
pub mod torch_file;

use crate::arch::{Architecture, SidUnetConfig};
use crate::error::{NnError, Result};
use crate::named::NamedTensor;
use crate::weights::{self, ImportedFrom, NoiseSource, WeightMeta};
use std::collections::BTreeMap;
use std::path::Path;

/// The repositories whose SID U-Net checkpoints pgrf knows the convention
/// of (`--from`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    /// Chen et al., Learning to See in the Dark (CVPR 2018).
    Sid,
    /// Wei et al., ELD (CVPR 2020).
    Eld,
    /// Feng et al., PMN (ACM MM 2022).
    Pmn,
    /// Feng et al., PNNP (2024).
    Pnnp,
    /// Jin et al., LED (ICCV 2023).
    Led,
}

impl std::str::FromStr for Source {
    type Err = pgrf_core::parse::ParseError;
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        Ok(match s.to_ascii_lowercase().as_str() {
            "sid" => Source::Sid,
            "eld" => Source::Eld,
            "pmn" => Source::Pmn,
            "pnnp" => Source::Pnnp,
            "led" => Source::Led,
            _ => {
                return Err(pgrf_core::parse::ParseError::unknown_name(
                    s,
                    format!("unknown source '{s}' (sid, eld, pmn, pnnp, led)"),
                ))
            }
        })
    }
}

impl Source {
    /// The name `--from` takes.
    pub fn name(self) -> &'static str {
        match self {
            Source::Sid => "sid",
            Source::Eld => "eld",
            Source::Pmn => "pmn",
            Source::Pnnp => "pnnp",
            Source::Led => "led",
        }
    }

    /// The repository's input and output convention and what it means for
    /// running the weights in pgrf (tests/reference/PUBLISHED_MODELS.md has
    /// the code each statement was read from).
    pub fn convention(self) -> &'static str {
        match self {
            Source::Sid => {
                "SID's released TensorFlow model ends in 12 channels and depth-to-space (raw in, sRGB \
                 out): it cannot be a raw-to-raw network, and no checkpoint of it has UNetSeeInDark's \
                 4-output conv10_1; a raw-to-raw port follows ELD's convention"
            }
            Source::Eld => {
                "input: packed R, G1, B, G2, (x - black) / (16383 - black), clipped to [0, 1], times \
                 the ratio, clipped to [0, 1]; output: 4 raw channels, clipped to [0, 1]; not \
                 residual. pgrf does the same but normalises by the file's white level: give \
                 --white 16383 for A7S2 ARW files (their metadata says 15360)"
            }
            Source::Pmn | Source::Pnnp => {
                "input: packed R, G1, B, G2, (x - 512) / (16383 - 512) after subtracting the \
                 calibrated dark shading (resources/SonyA7S2), times the ratio, clipped at 1 only \
                 (negative values reach the network); output: 4 raw channels, clipped to [0, 1]; \
                 not residual. pgrf clips to [0, 1] and subtracts a dark level only with --calib: \
                 give --white 16383 for A7S2 ARW files; the shift from the negatives and the dark \
                 shading is not measured"
            }
            Source::Led => {
                "input: packed R, G1, B, G2, (x - black) / (white - black) per channel, times the \
                 ratio, clipped at 1 only (negative values reach the network); output: 4 raw \
                 channels, clipped to [0, 1]; not residual; import the file's 'params' (or, for \
                 LED's fine-tuned models, 'params_deploy': --key params_deploy). pgrf clips to \
                 [0, 1]: the shift from the negatives is not measured. Licence CC BY-NC 4.0"
            }
        }
    }
}

/// An imported network, ready to be written as a pgrf weight file.
pub struct Imported {
    /// Its record (architecture, provenance).
    pub meta: WeightMeta,
    /// Its tensors in pgrf's names.
    pub tensors: BTreeMap<String, NamedTensor>,
}

impl Imported {
    /// The pgrf weight file's bytes (safetensors with the record).
    pub fn encode(&self) -> Result<Vec<u8>> {
        weights::encode(&self.tensors, &self.meta)
    }
}

/// Read the SID U-Net checkpoint at `path` (PyTorch `.pth`/`.pt`, zip or
/// legacy, or safetensors; the state dict at the top or nested under any
/// key such as `state_dict`, `model`, `netG`; `module.` prefixes
/// stripped), check every tensor by name and shape against
/// `UNetSeeInDark` at the width its first convolution has, and map it onto
/// pgrf's network.
/// `key`: the nesting to take when the file holds the network more than
/// once (LED's `params` and `params_ema`); by default the shortest.
pub fn import_sid(path: &Path, from: Option<Source>, key: Option<&str>) -> Result<Imported> {
    let file = torch_file::read(path)?;
    let (prefix, others) = nesting(path, &file.tensors, key)?;
    let torch: BTreeMap<String, &NamedTensor> = file
        .tensors
        .iter()
        .filter_map(|(k, v)| k.strip_prefix(&prefix).map(|n| (n.to_string(), v)))
        .collect();
    let (width, cin, cout) = check_unet(path, &torch, &prefix)?;
    let tensors: BTreeMap<String, NamedTensor> = sid_names::pairs()
        .into_iter()
        .map(|(t, p)| (p, torch[&t].clone()))
        .collect();

    let arch = Architecture::SidUnet(
        SidUnetConfig::new()
            .with_width(width)
            .with_in_channels(cin)
            .with_out_channels(cout)
            .with_residual(false),
    );
    let mut meta = WeightMeta::new(arch, NoiseSource::default());
    meta.imported = Some(ImportedFrom {
        file: path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        sha256: file.sha256.clone(),
        container: file.format.to_string(),
        nesting: prefix,
        also_under: others,
        repository: from.map(|s| s.name().to_string()),
        convention: from.map(|s| s.convention().to_string()),
    });
    Ok(Imported { meta, tensors })
}

/// The first convolution's weight, whose prefix is the network's nesting.
const ANCHOR: &str = "conv1_1.weight";

/// The nesting of the network in a checkpoint's tensors (whatever comes
/// before [`ANCHOR`]): `key`'s when given, else the shortest; and the other
/// nestings that hold one, for the record.
fn nesting(
    path: &Path,
    tensors: &BTreeMap<String, NamedTensor>,
    key: Option<&str>,
) -> Result<(String, Vec<String>)> {
    let mut prefixes: Vec<&str> = tensors
        .keys()
        .filter_map(|k| k.strip_suffix(ANCHOR))
        .filter(|p| p.is_empty() || p.ends_with('.'))
        .collect();
    prefixes.sort_by_key(|p| (p.len(), p.to_string()));
    if let Some(k) = key {
        let want = if k.is_empty() || k.ends_with('.') {
            k.to_string()
        } else {
            format!("{k}.")
        };
        if !prefixes.contains(&want.as_str()) {
            return Err(bad_file(
                path,
                format!(
                    "no UNetSeeInDark under '{k}' (found under: {})",
                    prefixes
                        .iter()
                        .map(|p| format!("'{}'", p.trim_end_matches('.')))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            ));
        }
        prefixes.retain(|p| *p == want);
    }
    let Some(&prefix) = prefixes.first() else {
        let some: Vec<&str> = tensors.keys().take(3).map(|k| k.as_str()).collect();
        return Err(bad_file(
            path,
            format!(
                "no {ANCHOR}: not a UNetSeeInDark checkpoint (its tensors start {})",
                if some.is_empty() {
                    "with none at all".to_string()
                } else {
                    some.join(", ")
                }
            ),
        ));
    };
    let others = prefixes
        .iter()
        .skip(1)
        .map(|p| p.trim_end_matches('.').to_string())
        .collect();
    Ok((prefix.to_string(), others))
}

/// Check the checkpoint's tensors (PyTorch names, nesting `prefix` removed)
/// are `UNetSeeInDark` raw to raw, every one by name, shape and finite
/// values, none left over: its (width, inputs, outputs).
fn check_unet(
    path: &Path,
    torch: &BTreeMap<String, &NamedTensor>,
    prefix: &str,
) -> Result<(usize, usize, usize)> {
    let first = &torch[ANCHOR];
    let last = torch
        .get("conv10_1.weight")
        .ok_or_else(|| bad_file(path, "conv10_1.weight is missing".into()))?;
    if first.shape.len() != 4 || last.shape.len() != 4 {
        return Err(bad_file(
            path,
            format!(
                "{ANCHOR} has shape {:?}: not a 2-D convolution",
                first.shape
            ),
        ));
    }
    let (width, cin, cout) = (first.shape[0], first.shape[1], last.shape[0]);
    if cin != 4 || cout != 4 {
        return Err(bad_file(path, format!(
            "the network takes {cin} channels and gives {cout}; pgrf's SID U-Net is raw to raw, 4 packed channels in and out{}",
            if cout == 12 {
                " (12 outputs: SID's sRGB model, which ends in depth-to-space)"
            } else {
                ""
            }
        )));
    }
    let expected = sid_names::torch_shapes(width, cin, cout);
    for (name, shape) in &expected {
        match torch.get(name) {
            None => {
                return Err(bad_file(path, format!(
                    "{prefix}{name} is missing or not a tensor (a UNetSeeInDark of width {width} has {} tensors)",
                    expected.len()
                )))
            }
            Some(t) if &t.shape != shape => {
                return Err(bad_file(path, format!(
                    "{prefix}{name} has shape {:?}, UNetSeeInDark of width {width} has {shape:?}",
                    t.shape
                )))
            }
            Some(t) => {
                if let Some(i) = t.values.iter().position(|v| !v.is_finite()) {
                    return Err(bad_file(path, format!(
                        "{prefix}{name} holds a non-finite value at index {i}"
                    )));
                }
            }
        }
    }
    let known: Vec<&String> = expected.iter().map(|(n, _)| n).collect();
    if let Some(extra) = torch.keys().find(|k| !known.contains(k)) {
        return Err(bad_file(
            path,
            format!("{prefix}{extra} is not part of UNetSeeInDark (another architecture?)"),
        ));
    }
    Ok((width, cin, cout))
}

/// The checkpoint at `path` refused for `reason`.
fn bad_file(path: &Path, reason: String) -> NnError {
    NnError::BadFile {
        path: path.to_path_buf(),
        reason,
    }
}

/// How [`export`] wrote a network.
pub struct Exported {
    /// The file's bytes.
    pub bytes: Vec<u8>,
    /// The naming used, in words.
    pub naming: &'static str,
    /// Whether the network adds its input to its output (the PyTorch side
    /// must do the same: `UNetSeeInDark` does not).
    pub residual: bool,
}

/// [`export`] of the weight file `model`, its tensors first checked to be
/// the network its record describes, by name and shape ([`crate::model`]'s
/// check, the one `enhance` makes): a file whose record and tensors
/// disagree is refused, never exported. Returns the record, the number of
/// tensors and the export.
pub fn export_file(model: &Path, pth: bool) -> Result<(WeightMeta, usize, Exported)> {
    let (meta, tensors) = crate::weights::read(model)?;
    crate::model::check_fit(model, &meta, &tensors)?;
    let out = export(&meta, &tensors, pth)?;
    Ok((meta, tensors.len(), out))
}

/// A pgrf weight file's network for PyTorch: `.pth` (torch.save's zip
/// format) when `pth`, else safetensors. The SID U-Net in UNetSeeInDark's
/// names, the SR3 network in pgrf's own.
pub fn export(
    meta: &WeightMeta,
    tensors: &BTreeMap<String, NamedTensor>,
    pth: bool,
) -> Result<Exported> {
    let (named, naming) = meta.arch.export_names(tensors)?;
    let residual = meta.arch.residual();
    let bytes = if pth {
        pth_write::encode(&named)?
    } else {
        let mut meta_map = std::collections::HashMap::new();
        meta_map.insert("format".to_string(), "pt".to_string());
        meta_map.insert("residual".to_string(), residual.to_string());
        let le_bytes: std::collections::HashMap<&str, Vec<u8>> = named
            .iter()
            .map(|(n, t)| {
                (
                    n.as_str(),
                    t.values.iter().flat_map(|v| v.to_le_bytes()).collect(),
                )
            })
            .collect();
        let views: Vec<(String, safetensors::tensor::TensorView<'_>)> = named
            .iter()
            .map(|(n, t)| {
                safetensors::tensor::TensorView::new(
                    safetensors::Dtype::F32,
                    t.shape.clone(),
                    &le_bytes[n.as_str()],
                )
                .map(|v| (n.clone(), v))
                .map_err(|e| NnError::Invalid(format!("tensor {n}: {e}")))
            })
            .collect::<Result<_>>()?;
        safetensors::tensor::serialize(views, Some(meta_map))
            .map_err(|e| NnError::Invalid(e.to_string()))?
    };
    Ok(Exported {
        bytes,
        naming,
        residual,
    })
}
