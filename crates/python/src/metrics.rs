//! `pgrf.metrics`: PSNR and SSIM as published low-light work measures them
//! (the ELD protocol, pgrf-eval's), so a score computed in a training loop
//! is the score `pgrf eval` prints.

use crate::errors::bad;
use crate::threads::run;
use numpy::PyReadonlyArray3;
use pgrf_eval::{evaluate as eval_pair, Protocol};
use pyo3::prelude::*;

fn protocol(name: &str, illuminance_correct: bool) -> PyResult<Protocol> {
    match name {
        "eld" => Ok(Protocol::eld(illuminance_correct)),
        "plain" if !illuminance_correct => Ok(Protocol {
            clamp: false,
            illuminance_correct: false,
            data_range: 1.0,
        }),
        "plain" => Err(bad(
            "metrics: illuminance_correct is part of the ELD protocol (protocol=\"eld\")",
        )),
        other => Err(bad(format!(
            "metrics: unknown protocol {other:?} (\"eld\": ELD's, clamped x255; \"plain\": scikit-image on the values as given, data range 1)"
        ))),
    }
}

/// scores(output, reference, protocol="eld", illuminance_correct=False)
/// -> (psnr, ssim, gain)
///
/// The low-level call behind `pgrf.metrics` (which documents it).
#[pyfunction]
#[pyo3(signature = (output, reference, protocol="eld", illuminance_correct=false))]
pub fn scores(
    py: Python<'_>,
    output: PyReadonlyArray3<'_, f32>,
    reference: PyReadonlyArray3<'_, f32>,
    protocol: &str,
    illuminance_correct: bool,
) -> PyResult<(f64, f64, Option<f64>)> {
    let p = self::protocol(protocol, illuminance_correct)?;
    let (o, r) = (output.as_array(), reference.as_array());
    let s = run(py, || eval_pair(o, r, &p))?;
    Ok((s.psnr, s.ssim, s.gain))
}
