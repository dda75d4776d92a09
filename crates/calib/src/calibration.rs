//! The calibration file: per-pixel maps in safetensors plus one JSON record of
//! how they were measured, and its conversion into the noise model's maps.

use crate::error::{invalid, Result};
use ndarray::Array3;
use pgrf_noise::mapfile::{read_maps, write_maps};
use pgrf_noise::{DarkLaw, Map, PixelMaps};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

/// Everything about how a calibration was made; units in `units`.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct CalibMeta {
    pub kind: String,
    pub schema: u32,
    pub pgrf_version: String,
    pub make: String,
    pub model: String,
    pub iso: Option<u32>,
    pub width: usize,
    pub height: usize,
    pub cfa: String,
    pub black: [f32; 4],
    pub white: u32,
    pub bias_frames: usize,
    pub bias_exposure_s: f64,
    pub dark_exposures_s: Vec<f64>,
    pub dark_frames: Vec<usize>,
    pub flat_exposures_s: Vec<f64>,
    pub flat_frames: Vec<usize>,
    /// System gain, DN per electron, and how it was estimated ("ptc" or "var/mean").
    #[serde(rename = "K")]
    pub k: f64,
    pub k_method: String,
    pub row_sigma: f64,
    pub read_sigma_median: f64,
    pub dsnu: f64,
    pub prnu: Option<f64>,
    /// "sqrt" or "linear", chosen by the better R^2 of the pixel-averaged dark signal.
    pub dark_law: String,
    pub dark_r2_sqrt: Option<f64>,
    pub dark_r2_linear: Option<f64>,
    pub dark_rate_mean: Option<f64>,
    pub ppcc_pixel_median: Option<f64>,
    pub ppcc_pooled: Option<f64>,
    pub hot_pixels: usize,
    pub dead_pixels: usize,
    pub units: String,
}

/// A loaded calibration.
#[derive(Clone, Debug)]
pub struct Calibration {
    pub meta: CalibMeta,
    pub maps: BTreeMap<String, Array3<f32>>,
}

/// Maps every calibration file must hold.
pub const REQUIRED_MAPS: [&str; 4] = ["fixed_pattern", "sigma_read", "dark_rate", "defects"];

impl Calibration {
    pub fn save(&self, path: &Path) -> Result<()> {
        let meta = serde_json::to_value(&self.meta).map_err(|e| invalid(e.to_string()))?;
        let views: Vec<(&str, ndarray::ArrayView3<f32>)> = self
            .maps
            .iter()
            .map(|(k, v)| (k.as_str(), v.view()))
            .collect();
        write_maps(path, &views, &meta)?;
        Ok(())
    }

    pub fn load(path: &Path) -> Result<Calibration> {
        let (meta, maps) = read_maps(path)?;
        if meta.get("kind").and_then(|k| k.as_str()) != Some("pgrf-calibration") {
            return Err(invalid(format!(
                "{}: not a pgrf calibration file",
                path.display()
            )));
        }
        let meta: CalibMeta = serde_json::from_value(meta)
            .map_err(|e| invalid(format!("{}: bad calibration record: {e}", path.display())))?;
        for m in REQUIRED_MAPS {
            if !maps.contains_key(m) {
                return Err(invalid(format!(
                    "{}: calibration has no '{m}' map",
                    path.display()
                )));
            }
        }
        let shape = [4, meta.height / 2, meta.width / 2];
        for (name, a) in &maps {
            if a.shape() != shape {
                return Err(invalid(format!(
                    "{}: map '{name}' has shape {:?}, the record says {:?}",
                    path.display(),
                    a.shape(),
                    shape
                )));
            }
        }
        let c = Calibration { meta, maps };
        c.to_pixel_maps()?.check_values()?;
        Ok(c)
    }

    /// Refuse to apply a calibration of another camera or ISO (unless forced).
    pub fn check_matches(
        &self,
        make: &str,
        model: &str,
        iso: Option<u32>,
        force: bool,
    ) -> Result<()> {
        if force {
            return Ok(());
        }
        let m = &self.meta;
        if (m.make.as_str(), m.model.as_str()) != (make, model) {
            return Err(invalid(format!(
                "calibration is of '{} {}', the frame is from '{make} {model}' (use --force to apply it anyway)",
                m.make, m.model
            )));
        }
        if m.iso.is_some() && iso.is_some() && m.iso != iso {
            return Err(invalid(format!(
                "calibration is for ISO {}, the frame is ISO {} (use --force to apply it anyway)",
                m.iso.unwrap_or(0),
                iso.unwrap_or(0)
            )));
        }
        Ok(())
    }

    /// The noise model's per-pixel maps. N_FP is not separated from the dark
    /// rate by this calibration (it is absorbed in it), so it is zero.
    pub fn to_pixel_maps(&self) -> Result<PixelMaps> {
        let get = |n: &str| -> Result<Map> {
            self.maps
                .get(n)
                .map(|a| Map::Pixel(Arc::new(a.clone())))
                .ok_or_else(|| invalid(format!("calibration has no '{n}' map")))
        };
        let law = match self.meta.dark_law.as_str() {
            "linear" => DarkLaw::Linear,
            _ => DarkLaw::Sqrt,
        };
        Ok(PixelMaps {
            bias: get("fixed_pattern")?,
            sigma_read: get("sigma_read")?,
            dark_rate: get("dark_rate")?,
            n_fp: Map::Scalar(0.0),
            dark_law: law,
        })
    }

    /// Make `spec` synthesise this sensor: its per-pixel maps, and the gain,
    /// row noise and DN scale they were measured with (maps are meaningless
    /// on another scale). The ISO is taken from the calibration when unset.
    pub fn apply_to(&self, spec: &mut pgrf_noise::pair::PairSpec) -> Result<()> {
        if spec.kind != pgrf_noise::ModelKind::Pgrf {
            return Err(invalid(format!(
                "a calibration applies to the pgrf noise model (per-pixel maps), not {:?}",
                spec.kind
            )));
        }
        let m = &self.meta;
        let black = m.black.iter().map(|&b| b as f64).sum::<f64>() / 4.0;
        spec.maps = Some(self.to_pixel_maps()?);
        spec.measured = Some(pgrf_noise::pair::Measured {
            k: m.k,
            row_sigma: m.row_sigma,
            dn_range: m.white as f64 - black,
            black,
        });
        if spec.iso.is_none() {
            spec.iso = m.iso;
        }
        Ok(())
    }

    /// Expected dark level above black in DN per packed pixel for an exposure
    /// of `exposure_s`: the fixed pattern plus the mean dark current
    /// (rate x law(t) electrons x K DN per electron). This is what dark-frame
    /// subtraction removes before a photo is amplified; the random part of
    /// the dark signal stays for the denoiser.
    pub fn dark_shading_dn(&self, exposure_s: f64) -> Result<Array3<f32>> {
        if !(exposure_s.is_finite() && exposure_s >= 0.0) {
            return Err(invalid(format!(
                "exposure time must be a non-negative number of seconds, got {exposure_s}"
            )));
        }
        let get = |n: &str| {
            self.maps
                .get(n)
                .ok_or_else(|| invalid(format!("calibration has no '{n}' map")))
        };
        let law = match self.meta.dark_law.as_str() {
            "linear" => DarkLaw::Linear,
            _ => DarkLaw::Sqrt,
        };
        let dn_per_rate = law.electrons(1.0, exposure_s) * self.meta.k;
        let mut out = get("fixed_pattern")?.clone();
        ndarray::Zip::from(&mut out)
            .and(get("dark_rate")?)
            .for_each(|o, &r| *o += (r as f64 * dn_per_rate) as f32);
        Ok(out)
    }

    /// A short identity for records: camera, ISO and file name.
    pub fn identity(&self, path: &Path) -> String {
        format!(
            "{} {} ISO {} ({})",
            self.meta.make,
            self.meta.model,
            self.meta
                .iso
                .map(|i| i.to_string())
                .unwrap_or_else(|| "?".into()),
            path.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default()
        )
    }
}
