//! Dataset protocols: which noisy/reference files a benchmark pairs, at which
//! exposure ratio, and how a pair is loaded before it is measured. The
//! *measurement* (clamp, gain, PSNR/SSIM) is [`crate::metrics::Protocol`];
//! this layer decides *what* is measured.
//!
//! - [`eld`]: the ELD Sony A7S2 folder layout (ELD's `ELDEvalDataset`).
//! - [`sid`]: the SID Sony test list, as ELD evaluates SID (`test_SID.py`).
//! - [`pairs`]: a user's own CSV of noisy, reference, ratio.
//! - [`synthetic`]: clean RAW files (or photos, unprocessed) made dark and
//!   noisy in memory at a grid of ISO x ratio conditions with fixed seeds.
//!
//! Walkers only look at the file system (every file they name must exist,
//! else an error naming it); pixels and EXIF are read by `load_pair`.
//! Loading follows ELD's datasets (`pack_raw_bayer`, `ELDEvalDataset`,
//! `SIDDataset`): noisy packed R,G1,B,G2, normalised by black per channel
//! and the white level (16383 for ELD/SID, see
//! [`DatasetKind::default_white`]), multiplied by the ratio and clipped at 1
//! (values below black kept; a network that reads them clamped clamps them
//! itself); reference packed, normalised and clamped to [0, 1].

pub mod eld;
pub mod miniature;
pub mod pairs;
pub mod run;
pub mod sid;
pub mod synthetic;
pub mod table;

use crate::method::CaseNoise;
use ndarray::{s, Array3, ArrayView3};
use pgrf_core::parse::ParseError;
use pgrf_noise::lookup::{find_noise, range_of, KnownNoise};
use pgrf_raw::{decode_file, pack_normalized, LevelOverrides, RawFrame};
use std::fmt;
use std::path::{Path, PathBuf};

/// One line, naming the file or setting at fault.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct DatasetError(pub(crate) String);

pub(crate) type Result<T> = std::result::Result<T, DatasetError>;

fn err<T>(msg: impl Into<String>) -> Result<T> {
    Err(DatasetError(msg.into()))
}

/// Which benchmark a sample belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DatasetKind {
    /// ELD's Sony A7S2 set ([`eld`]).
    Eld,
    /// SID's Sony test list, as ELD evaluates it ([`sid`]).
    Sid,
    /// A user's own CSV of pairs ([`pairs`]).
    Pairs,
    /// Dark captures synthesised from clean files ([`synthetic`]).
    Synthetic,
}

impl DatasetKind {
    pub(crate) fn name(self) -> &'static str {
        match self {
            DatasetKind::Eld => "eld",
            DatasetKind::Sid => "sid",
            DatasetKind::Pairs => "pairs",
            DatasetKind::Synthetic => "synthetic",
        }
    }

    /// The protocol's own illuminance-correction setting: ELD's `test_ELD.py`
    /// and `test_SID.py` both call `engine.eval(..., correct=True)`; a user's
    /// pairs are measured without it unless asked, and so are synthetic
    /// captures, whose exposure is known exactly.
    pub fn default_correct(self) -> bool {
        matches!(self, DatasetKind::Eld | DatasetKind::Sid)
    }

    /// The protocol's white level: ELD's `pack_raw_bayer` normalises by
    /// `(x - black[c]) / (16383 - black[c])` whatever the file says (Sony's
    /// compressed ARW reports 15360), black per channel from the file; a
    /// user's pairs and synthetic captures use each file's own levels.
    pub fn default_white(self) -> Option<u32> {
        match self {
            DatasetKind::Eld | DatasetKind::Sid => Some(16383),
            DatasetKind::Pairs | DatasetKind::Synthetic => None,
        }
    }

    /// The protocol's own centre crop (packed pixels): ELD measures SID on
    /// the centre 512x512 of the packed planes (`crop=True`) and ELD's own
    /// set on full images (`crop=False`).
    pub fn default_crop(self) -> Option<usize> {
        match self {
            DatasetKind::Sid => Some(512),
            _ => None,
        }
    }
}

impl fmt::Display for DatasetKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for DatasetKind {
    type Err = ParseError;
    fn from_str(s: &str) -> std::result::Result<Self, ParseError> {
        match s.to_ascii_lowercase().as_str() {
            "eld" => Ok(DatasetKind::Eld),
            "sid" => Ok(DatasetKind::Sid),
            "pairs" => Ok(DatasetKind::Pairs),
            "synthetic" => Ok(DatasetKind::Synthetic),
            _ => Err(ParseError::unknown_name(
                s,
                format!("unknown protocol {s:?}: expected eld, sid, pairs or synthetic"),
            )),
        }
    }
}

/// How a sample's amplification is found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum RatioRule {
    /// (ISO x exposure time) of the reference over that of the noisy frame,
    /// both from the files' EXIF (ELD's `metainfo`).
    IsoExposure,
    /// Given by the list (SID's exposure times from the file names, or a
    /// CSV's ratio column).
    Fixed(f32),
}

/// One noisy/reference pair of a benchmark.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    pub(crate) kind: DatasetKind,
    /// Scene/pair identifier for tables and CSV ("scene-3/IMG_0009", "10003_00_0.1s").
    pub(crate) id: String,
    /// The table row the pair is averaged into (100, 200, 250, 300, ...).
    pub(crate) group: u32,
    pub(crate) ratio: RatioRule,
    pub(crate) noisy: PathBuf,
    pub(crate) reference: PathBuf,
}

/// A loaded pair, ready for a network and the metrics.
pub(crate) struct LoadedPair {
    pub(crate) reference_frame: RawFrame,
    /// Packed noisy x ratio, clamped to [0, 1]: the network input, and the
    /// "noisy input" baseline.
    pub(crate) input: Array3<f32>,
    /// Packed reference clamped to [0, 1].
    pub(crate) reference: Array3<f32>,
    pub(crate) ratio: f32,
    /// The capture's noise as a noise-aware method is told it.
    pub(crate) noise: Option<CaseNoise>,
}

/// (ISO x exposure) of a frame, for ELD's ratio.
fn iso_exposure(f: &RawFrame, path: &Path) -> Result<f64> {
    match (f.iso.filter(|i| *i > 0), f.exposure_s.filter(|t| *t > 0.0)) {
        (Some(i), Some(t)) => Ok(i as f64 * t),
        _ => err(format!(
            "{}: the file records no ISO or exposure time, needed for the exposure ratio",
            path.display()
        )),
    }
}

/// Decode both files of `s` (with `levels` overriding the files' black or
/// white levels), compute the ratio, and pack them.
pub(crate) fn load_pair(s: &Sample, levels: &LevelOverrides) -> Result<LoadedPair> {
    let (n, r) = rayon::join(
        || decode_file(&s.noisy, levels),
        || decode_file(&s.reference, levels),
    );
    let n = n.map_err(|e| DatasetError(e.to_string()))?;
    let r = r.map_err(|e| DatasetError(e.to_string()))?;
    if (n.width, n.height, n.layout()) != (r.width, r.height, r.layout()) {
        return err(format!(
            "{} ({}x{} {}) and {} ({}x{} {}) differ in size or CFA phase",
            s.noisy.display(),
            n.width,
            n.height,
            n.layout(),
            s.reference.display(),
            r.width,
            r.height,
            r.layout()
        ));
    }
    let ratio = match s.ratio {
        RatioRule::Fixed(v) => v,
        RatioRule::IsoExposure => {
            (iso_exposure(&r, &s.reference)? / iso_exposure(&n, &s.noisy)?) as f32
        }
    };
    if !(ratio.is_finite() && ratio > 0.0) {
        return err(format!("{}: exposure ratio {ratio} is not positive", s.id));
    }
    let mut input = pack_normalized(&n, false).map_err(|e| DatasetError(e.to_string()))?;
    // Clipped at white only: a network that reads values below black
    // clamped clamps them itself.
    input.mapv_inplace(|v| (v * ratio).min(1.0));
    let reference = pack_normalized(&r, true).map_err(|e| DatasetError(e.to_string()))?;
    // What the lookup finds for the noisy file (None where nothing can be
    // found: only a noise-aware method needs it, and says so).
    let noise = find_noise(&n, &KnownNoise::default())
        .ok()
        .map(|f| CaseNoise {
            k: f.k,
            read: f.read,
            row: f.row,
            range: range_of(&n),
            source: f.source.to_string(),
        });
    Ok(LoadedPair {
        reference_frame: r,
        input,
        reference,
        ratio,
        noise,
    })
}

/// ELD's `crop_center` (`util.crop_center`) on packed planes: the centre `side` x `side` window
/// starting at (h/2 - side/2, w/2 - side/2); a plane smaller than `side` is
/// kept whole along that axis.
pub(crate) fn centre_crop(a: ArrayView3<'_, f32>, side: Option<usize>) -> ArrayView3<'_, f32> {
    let Some(side) = side else { return a };
    let (_, h, w) = a.dim();
    let (ch, cw) = (side.min(h), side.min(w));
    let (y0, x0) = (h / 2 - ch / 2, w / 2 - cw / 2);
    a.slice_move(s![.., y0..y0 + ch, x0..x0 + cw])
}

/// The first of `candidates` that exists, else an error naming the first
/// (the name the protocol prescribes).
pub(crate) fn existing(candidates: &[PathBuf], what: &str) -> Result<PathBuf> {
    for c in candidates {
        if c.is_file() {
            return Ok(c.clone());
        }
    }
    let alts: Vec<String> = candidates[1..]
        .iter()
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    let also = if alts.is_empty() {
        String::new()
    } else {
        format!(" (nor {})", alts.join(", "))
    };
    err(format!(
        "missing {what}: {} not found{also}",
        candidates[0].display()
    ))
}

/// `path` and the same stem with the other raw extensions pgrf accepts in a
/// benchmark folder (.ARW as published, .dng as `pgrf make-dataset` writes).
pub(crate) fn with_alternatives(path: &Path) -> Vec<PathBuf> {
    let mut v = vec![path.to_path_buf()];
    for ext in ["ARW", "arw", "dng", "DNG"] {
        let p = path.with_extension(ext);
        if !v.contains(&p) {
            v.push(p);
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_crop_matches_eld() {
        let a = Array3::from_shape_fn((4, 10, 12), |(c, i, j)| (c * 1000 + i * 100 + j) as f32);
        let c = centre_crop(a.view(), Some(4));
        assert_eq!(c.dim(), (4, 4, 4));
        // starty = 10/2 - 2 = 3, startx = 12/2 - 2 = 4.
        assert_eq!(c[[0, 0, 0]], 304.0);
        let c = centre_crop(a.view(), Some(64));
        assert_eq!(c.dim(), (4, 10, 12));
        assert_eq!(centre_crop(a.view(), None).dim(), (4, 10, 12));
    }

    #[test]
    fn protocol_defaults() {
        assert!(DatasetKind::Eld.default_correct());
        assert!(DatasetKind::Sid.default_correct());
        assert!(!DatasetKind::Pairs.default_correct());
        assert_eq!(DatasetKind::Sid.default_crop(), Some(512));
        assert_eq!(DatasetKind::Eld.default_crop(), None);
        assert_eq!(DatasetKind::Eld.default_white(), Some(16383));
        assert_eq!(DatasetKind::Pairs.default_white(), None);
        assert!(!DatasetKind::Synthetic.default_correct());
        assert_eq!(DatasetKind::Synthetic.default_white(), None);
        assert_eq!(DatasetKind::Synthetic.default_crop(), None);
        assert_eq!("synthetic".parse(), Ok(DatasetKind::Synthetic));
    }
}
