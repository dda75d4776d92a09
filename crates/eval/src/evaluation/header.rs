//! The header of an evaluation: what is measured (the protocol's cases),
//! how (crop, levels, input, ELD's measurement) and, for synthetic runs, the
//! colour-cast definition, so a printed table always says how it was made.

use super::EvalConfig;
use crate::cast;
use crate::dataset::run::NOISY;
use crate::dataset::synthetic::{self, Synthetic};
use crate::dataset::{sid, DatasetKind, Sample};
use crate::Protocol;

/// What a file-pair run measures, for the header's first line.
pub(super) fn pairs_description(cfg: &EvalConfig, samples: &[Sample]) -> String {
    let what = match cfg.protocol {
        DatasetKind::Eld => format!(
            "ELD Sony A7S2, scenes {}: x100 = frames 4,9,14, x200 = frames 5,10,15, reference = nearest of frames 1,6,11,16, ratio = ISO x exposure of reference / noisy (EXIF)",
            cfg.scenes
        ),
        DatasetKind::Sid => format!(
            "SID Sony, {}: ratio = long / short exposure from file names, capped at 300; {}",
            cfg.list
                .as_ref()
                .map(|p| p.display().to_string())
                .unwrap_or_else(|| sid::DEFAULT_LIST.into()),
            if cfg.keep_misaligned {
                "misaligned 10034, 10045, 10172 kept"
            } else {
                "misaligned 10034, 10045, 10172 excluded"
            }
        ),
        DatasetKind::Pairs => format!("pairs of {}", cfg.roots[0].display()),
        DatasetKind::Synthetic => "synthetic captures".into(),
    };
    format!("{what}; {} images", samples.len())
}

/// What a synthetic run measures, for the header's first line.
pub(super) fn synthetic_description(images: &[synthetic::Image], synth: &Synthetic) -> String {
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
pub(super) fn header(cfg: &EvalConfig, what: &str) -> String {
    let synthetic = cfg.protocol == DatasetKind::Synthetic;
    let crop = match cfg.crop {
        Some(c) => {
            format!("centre {c}x{c} of the packed planes (input cropped before the network)")
        }
        None => "full image".into(),
    };
    let white = match cfg.white {
        Some(w) => format!("white {w}"),
        None => "white from each file".into(),
    };
    let input = if synthetic && cfg.synthetic.uncalibrated {
        "capture = reference / ratio through the noise model, x ratio, its dark-level offset (the profile's black-level error at the ISO) kept, uncalibrated, clamped [0,1]"
    } else if synthetic {
        "capture = reference / ratio through the noise model, x ratio, minus its dark-level offset (the profile's black-level error at the ISO, calibrated), clamped [0,1]"
    } else {
        "input x ratio clamped [0,1]"
    };
    let mut s = format!(
        "protocol {}: {what}; {crop}\nmeasure  packed R,G1,B,G2, black per channel from the files, {white}; {input}, reference clamped [0,1]; {}{}",
        cfg.protocol,
        Protocol::eld(cfg.correct).describe(),
        if cfg.correct && cfg.baseline {
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
