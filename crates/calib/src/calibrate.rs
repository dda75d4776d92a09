//! One calibration run: read the stacks, estimate, assemble the file.

use crate::calibration::{CalibMeta, Calibration};
use crate::error::{invalid, Result};
use crate::estimate::{
    defects, estimate_bias, estimate_dark, estimate_gain, median_of, BiasEstimate, DarkEstimate,
    GainEstimate,
};
use crate::stack::{read_stack, ReadOptions};
use pgrf_noise::DarkLaw;
use std::collections::BTreeMap;
use std::path::PathBuf;

pub struct CalibrateInput {
    pub bias: Vec<PathBuf>,
    pub dark: Vec<PathBuf>,
    pub flat: Vec<PathBuf>,
    /// Expected ISO; frames of another ISO are refused. Used when files carry none.
    pub iso: Option<u32>,
    /// Pixels whose temporal samples are kept for the normality check.
    pub tap_pixels: usize,
}

pub struct CalibrationRun {
    pub calibration: Calibration,
    pub bias: BiasEstimate,
    pub gain: GainEstimate,
    pub dark: Option<DarkEstimate>,
}

pub fn calibrate(input: &CalibrateInput, progress: &(dyn Fn() + Sync)) -> Result<CalibrationRun> {
    let bias_stack = read_stack(
        &input.bias,
        &ReadOptions {
            kind: "bias",
            expect: None,
            single_exposure: true,
            need_exposure: false,
            tap_pixels: input.tap_pixels,
            progress,
        },
    )?;
    let mut key = bias_stack.key.clone();
    if let (Some(want), Some(got)) = (input.iso, key.iso) {
        if want != got {
            return Err(invalid(format!(
                "bias frames are ISO {got} ({}), --iso asked for {want}",
                input.bias[0].display()
            )));
        }
    }
    if key.iso.is_none() {
        key.iso = input.iso;
    }
    let bias = estimate_bias(&bias_stack, key.black)?;
    let opts = |kind| ReadOptions {
        kind,
        expect: Some(&bias_stack.key),
        single_exposure: false,
        need_exposure: true,
        tap_pixels: 0,
        progress,
    };
    let flat_stack = read_stack(&input.flat, &opts("flat"))?;
    let gain = estimate_gain(&flat_stack, &bias)?;
    let (dark, dark_frames) = if input.dark.is_empty() {
        (None, Vec::new())
    } else {
        let dark_stack = read_stack(&input.dark, &opts("dark"))?;
        let frames = dark_stack.groups.iter().map(|g| g.files.len()).collect();
        (Some(estimate_dark(&dark_stack, &bias, gain.k)?), frames)
    };
    let defect_map = defects(&bias, Some(&gain), dark.as_ref());

    let mut maps = BTreeMap::new();
    maps.insert("fixed_pattern".to_string(), bias.fixed_pattern.clone());
    maps.insert("sigma_read".to_string(), bias.sigma_read.clone());
    maps.insert("gain".to_string(), gain.k_map.clone());
    maps.insert("response".to_string(), gain.response.clone());
    maps.insert("defects".to_string(), defect_map.clone());
    match &dark {
        Some(d) => {
            maps.insert("dark_rate".to_string(), d.rate.clone());
            maps.insert("r2_sqrt".to_string(), d.r2_sqrt.clone());
            maps.insert("r2_linear".to_string(), d.r2_linear.clone());
        }
        None => {
            maps.insert(
                "dark_rate".to_string(),
                ndarray::Array3::zeros(bias.fixed_pattern.raw_dim()),
            );
        }
    }
    let mut pp = bias.ppcc_pixels.clone();
    pp.sort_by(|a, b| a.total_cmp(b));
    let meta = CalibMeta {
        kind: "pgrf-calibration".into(),
        schema: 1,
        pgrf_version: env!("CARGO_PKG_VERSION").into(),
        make: key.make.clone(),
        model: key.model.clone(),
        iso: key.iso,
        width: key.width,
        height: key.height,
        cfa: key.cfa.name().into(),
        black: key.black,
        white: key.white,
        bias_frames: bias.frames,
        bias_exposure_s: bias_stack.groups[0].exposure_s,
        dark_exposures_s: dark.as_ref().map(|d| d.exposures.clone()).unwrap_or_default(),
        dark_frames,
        flat_exposures_s: gain.levels.iter().map(|l| l.exposure_s).collect(),
        flat_frames: gain.levels.iter().map(|l| l.frames).collect(),
        k: gain.k,
        k_method: gain.method.into(),
        row_sigma: bias.row_sigma,
        read_sigma_median: median_of(&bias.sigma_read),
        dsnu: bias.dsnu,
        prnu: Some(gain.prnu),
        dark_law: match dark.as_ref().map(|d| d.law) {
            Some(DarkLaw::Linear) => "linear".into(),
            Some(DarkLaw::Sqrt) => "sqrt".into(),
            None => "none".into(),
        },
        dark_r2_sqrt: dark.as_ref().map(|d| d.r2_sqrt_global),
        dark_r2_linear: dark.as_ref().map(|d| d.r2_linear_global),
        dark_rate_mean: dark.as_ref().map(|d| d.rate_mean),
        ppcc_pixel_median: pp.get(pp.len() / 2).copied(),
        ppcc_pooled: bias.ppcc_pooled.is_finite().then_some(bias.ppcc_pooled),
        hot_pixels: defect_map.iter().filter(|&&d| d == 1.0).count(),
        dead_pixels: defect_map.iter().filter(|&&d| d == 2.0).count(),
        units: "maps packed (4, H/2, W/2) in R,G1,B,G2 order; fixed_pattern (bias mean - black), sigma_read, response: DN; gain: DN per electron (eq. 3.15 per pixel); dark_rate: electrons per sqrt(s) (sqrt law) or per s (linear law), N_FP absorbed; defects: 0 good, 1 hot, 2 dead; r2_*: R^2 of the per-pixel dark fits; K, row_sigma, read_sigma_median, dsnu: DN (K: DN/e-)".into(),
    };
    Ok(CalibrationRun {
        calibration: Calibration { meta, maps },
        bias,
        gain,
        dark,
    })
}
