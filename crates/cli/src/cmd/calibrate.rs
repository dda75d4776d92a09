//! `pgrf calibrate`: bias, dark and flat stacks in, a per-pixel calibration
//! file and a readable report out.

use crate::progress::Bar;
use anyhow::Result;
use pgrf_calib::{calibrate_to_files, CalibrationRun, RunHooks};
use pgrf_report::{write_report, PtcPoint, ReportData, REPORT_FILES};
use std::path::Path;

pub use pgrf_calib::flags::CalibrateArgs;

pub fn run(a: &CalibrateArgs) -> Result<()> {
    let config = a.config(&REPORT_FILES)?;
    let c = &config.input;
    let total = c.bias.len() + c.flat.len() + c.dark.len();
    let bar = Bar::new("calibrating", total as u64, "frames", false);
    let outcome = calibrate_to_files(&config, &bar, &Cli)?;
    for line in outcome.messages(&config) {
        eprintln!("{line}");
    }
    if a.json {
        println!("{}", outcome.run.json_record(&a.output));
    }
    Ok(())
}

/// The CLI's part of the run: the report's plots (pgrf-report, which
/// pgrf-calib does not depend on).
struct Cli;

impl RunHooks for Cli {
    type Error = anyhow::Error;

    fn write_report(&self, dir: &Path, run: &CalibrationRun) -> Result<usize> {
        Ok(write_report(dir, &report_data(run))?.len())
    }
}

fn report_data(run: &CalibrationRun) -> ReportData<'_> {
    let m = &run.calibration.meta;
    let maps = &run.calibration.maps;
    ReportData {
        camera: format!("{} {}", m.make, m.model),
        iso: m.iso,
        ptc_points: run
            .gain
            .levels
            .iter()
            .map(|l| PtcPoint {
                mean_dn: l.mean_dn,
                var_dn2: l.var_dn2,
            })
            .collect(),
        ptc_fit: run.gain.ptc_fit,
        sigma_read: maps.sigma_read.view(),
        fixed_pattern: maps.fixed_pattern.view(),
        r2_sqrt: maps.r2_sqrt.as_ref().map(|a| a.view()),
        r2_linear: maps.r2_linear.as_ref().map(|a| a.view()),
        dark_offset: m.dark_offset,
        read_sigma_median: Some(m.read_sigma_median),
        temperature_c: m.temperature_c,
        dark_var_dn2: run.dark_variance(),
        mono: m.layout() == "mono",
        summary: run.summary(),
    }
}
