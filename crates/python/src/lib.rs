//! The `pgrf._pgrf` extension module: pgrf's RAW reading, noise synthesis,
//! unprocessing, calibration, metrics and networks for Python, numpy in and out. The
//! Python package `pgrf` (crates/python/python/pgrf) wraps it with
//! dataclasses, conversions and documentation; each function here makes one
//! library call, releases the GIL while it works (`threads::run`) and
//! raises pgrf's own message as `ValueError` or `OSError` (module `errors`).

use pyo3::prelude::*;

mod calibrate;
mod errors;
mod frame;
mod metrics;
mod model;
mod profile;
mod synth;
mod threads;
mod unprocess;

#[pymodule]
fn _pgrf(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<frame::Header>()?;
    m.add_class::<profile::Profile>()?;
    m.add_class::<calibrate::Calibration>()?;
    m.add_class::<model::Network>()?;
    m.add_function(wrap_pyfunction!(frame::read, m)?)?;
    m.add_function(wrap_pyfunction!(frame::write_dng, m)?)?;
    m.add_function(wrap_pyfunction!(frame::read_photo, m)?)?;
    m.add_function(wrap_pyfunction!(synth::synth, m)?)?;
    m.add_function(wrap_pyfunction!(synth::synth_batch, m)?)?;
    m.add_function(wrap_pyfunction!(unprocess::unprocess, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate::calibrate, m)?)?;
    m.add_function(wrap_pyfunction!(metrics::scores, m)?)?;
    m.add_function(wrap_pyfunction!(threads::set_threads, m)?)?;
    m.add_function(wrap_pyfunction!(threads::get_threads, m)?)?;
    Ok(())
}
