//! What `pgrf calibrate` says about a finished run: its lines for the
//! terminal and its global results as one JSON record, made here so that
//! every caller of the recipe reports a run the same way.

use crate::outputs::{CalibrateConfig, CalibrateOutcome, DarktableOutcome};
use crate::CalibrationRun;
use std::path::Path;

impl CalibrateOutcome {
    /// What the run wrote and found, one line each, for stderr: notes,
    /// the files written, warnings and dropped frames, then the global
    /// results.
    pub fn messages(&self, config: &CalibrateConfig) -> Vec<String> {
        let mut lines = Vec::new();
        if let DarktableOutcome::Skipped { lack } = &self.darktable {
            lines.push(format!(
                "pgrf: note: the frames {lack}: no darktable noise profile written"
            ));
        }
        if let (Some(n), Some(dir)) = (self.masters, &config.masters) {
            lines.push(format!(
                "wrote {n} master frames and defects.png in {}",
                dir.display()
            ));
        }
        if let (Some(n), Some(r)) = (self.report, &config.report) {
            lines.push(format!("wrote report: {n} files in {}", r.dir.display()));
        }
        if let DarktableOutcome::Written {
            path,
            replaced,
            name,
        } = &self.darktable
        {
            let replacing = match replaced {
                0 => String::new(),
                n => format!(", replacing {n} entry of that camera at that ISO"),
            };
            lines.push(format!(
                "wrote {}: darktable noise-profile entry \"{name}\"{replacing} (darktable reads the file with: darktable --noiseprofiles {})",
                path.display(),
                path.display()
            ));
        }
        let m = &self.run.calibration.meta;
        lines.extend(m.warnings.iter().map(|w| format!("pgrf: warning: {w}")));
        lines.extend(
            m.rejected_frames
                .iter()
                .map(|r| format!("pgrf: note: dropped {r}")),
        );
        lines.push(format!(
            "wrote {}: K {:.4} DN/e- ({}), read sigma median {:.3} DN, temporal dark noise {} DN (EMVA 1288, bias pairs), row sigma {:.3} DN, DSNU {:.3} DN, dark law {}, {} hot / {} dead pixels",
            config.output.display(),
            m.k,
            m.k_method,
            m.read_sigma_median,
            m.dark_noise_sigma
                .map_or_else(|| "-".into(), |d| format!("{d:.3}")),
            m.row_sigma,
            m.dsnu,
            crate::calibrate::law_label(m.dark_law, m.dark_offset),
            m.hot_pixels,
            m.dead_pixels
        ));
        lines.extend(self.run.extra_lines());
        lines
    }
}

impl CalibrationRun {
    /// What the run measured beyond the usual figures, a line each: the
    /// dark current's doubling temperature and the noise bank kept.
    fn extra_lines(&self) -> Vec<String> {
        let m = &self.calibration.meta;
        let mut lines = Vec::new();
        if let Some(d) = m.dark_doubling_c {
            let at: Vec<String> = (m.dark_rates_by_temperature.iter())
                .map(|(t, r)| format!("{r:.3} at {t:.1} °C"))
                .collect();
            lines.push(format!(
                "dark current doubles every {d:.2} °C (rates {} DN per unit of g(t)): `pgrf reduce` scales a light's dark to its temperature within {} °C",
                at.join(", "),
                crate::temperature::DARK_SCALE_RANGE_C
            ));
        }
        let bank = &self.calibration.maps.noise_bank;
        if let Some(f) = bank.first() {
            let (_, h, w) = f.dim();
            lines.push(format!(
                "noise bank: {} bias frames' residuals of {}x{} photosites ({:.1} MiB) for `pgrf synth --noise-bank`",
                bank.len(),
                2 * w,
                2 * h,
                (bank.len() * f.len() * 4) as f64 / (1u64 << 20) as f64
            ));
        }
        lines
    }

    /// The run's global results as one JSON record (`pgrf calibrate
    /// --json`), naming the calibration file `output`.
    pub fn json_record(&self, output: &Path) -> serde_json::Value {
        let m = &self.calibration.meta;
        serde_json::json!({
            "K": m.k,
            "K_method": m.k_method,
            "row_sigma": m.row_sigma,
            "read_sigma_median": m.read_sigma_median,
            "dark_noise_sigma": m.dark_noise_sigma,
            "dsnu": m.dsnu,
            "prnu": m.prnu,
            "dark_law": crate::calibrate::law_name(m.dark_law),
            "dark_r2_sqrt": m.dark_r2_sqrt,
            "dark_r2_linear": m.dark_r2_linear,
            "dark_rate_mean": m.dark_rate_mean,
            "dark_rate_unit": m.dark_rate_unit(),
            "dark_offset": m.dark_offset,
            "dark_offset_mean": m.dark_offset_mean,
            "K_without_pairs": self.gain.k_without_pairs,
            "noise_profile": self.noise_profile(),
            "cfa": m.layout(),
            "temperature_c": m.temperature_c,
            "warnings": m.warnings,
            "rejected_frames": m.rejected_frames,
            "hot_pixels": m.hot_pixels,
            "dead_pixels": m.dead_pixels,
            "output": output.display().to_string(),
        })
    }
}
