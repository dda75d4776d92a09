//! `pgrf.calibrate`: a per-pixel calibration from bias, flat and dark
//! stacks, by the library call `pgrf calibrate` makes, and the calibration
//! file's content (maps as arrays, the record as JSON).

use crate::errors::to_py;
use crate::threads::run;
use numpy::IntoPyArray;
use pgrf_calib::{CalibrateInput, Calibration as Cal};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// A sensor's per-pixel calibration: `maps` (packed `(4, H/2, W/2)`
/// arrays by name), `record_json` (how it was made and the global
/// figures), `save(path)` to pgrf's file.
#[pyclass(frozen, module = "pgrf._pgrf", name = "CalibrationData")]
pub struct Calibration {
    cal: Cal,
}

#[pymethods]
impl Calibration {
    /// CalibrationData.load(path) -> CalibrationData
    ///
    /// Read a calibration file (`pgrf calibrate`'s .safetensors).
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Calibration> {
        let cal = run(py, || Cal::load(&path))?;
        Ok(Calibration { cal })
    }

    /// The per-pixel maps, packed `(4, H/2, W/2)` float32, by name.
    #[getter]
    fn maps<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (name, m) in self.cal.maps.named() {
            d.set_item(name, m.clone().into_pyarray(py))?;
        }
        Ok(d)
    }

    /// The record (camera, ISO, levels, frames, gain, read and row noise,
    /// dark law, ...) as JSON text, as the file stores it.
    #[getter]
    fn record_json(&self) -> PyResult<String> {
        serde_json::to_string(&self.cal.meta).map_err(to_py)
    }

    /// save(path) -> None: write pgrf's calibration file (temporary file and rename).
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        run(py, || self.cal.save(&path))
    }
}

/// calibrate(bias, flat, dark=(), iso=None, reject=False,
/// temperature_tolerance=None) -> CalibrationData
///
/// The low-level call behind `pgrf.calibrate` (which documents it).
#[pyfunction]
#[pyo3(signature = (bias, flat, dark=Vec::new(), iso=None, reject=false, temperature_tolerance=None))]
pub fn calibrate(
    py: Python<'_>,
    bias: Vec<PathBuf>,
    flat: Vec<PathBuf>,
    dark: Vec<PathBuf>,
    iso: Option<u32>,
    reject: bool,
    temperature_tolerance: Option<f32>,
) -> PyResult<Calibration> {
    let input = CalibrateInput {
        bias,
        dark,
        flat,
        iso,
        tap_pixels: 4096,
        masters: false,
        temperature_tolerance,
        reject,
        temperature_darks: Vec::new(),
    };
    let run_ = run(py, || pgrf_calib::calibrate(&input, &pgrf_core::NoProgress))?;
    Ok(Calibration {
        cal: run_.calibration,
    })
}
