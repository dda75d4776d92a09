//! pgrf's errors as Python exceptions: `OSError` when a file could not be
//! read or written, `ValueError` for everything pgrf refused about the
//! input; the message is the one line the `pgrf` command prints (the error
//! and its causes), so a Python user reads what a CLI user reads.

use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::PyErr;
use std::error::Error;

/// The error and each cause it names, joined as the CLI's one-line report
/// joins them; a cause already contained in the line is not repeated.
pub fn chain(e: &(dyn Error + 'static)) -> String {
    let mut line = e.to_string();
    let mut next = e.source();
    while let Some(cause) = next {
        let text = cause.to_string();
        if !line.contains(&text) {
            line.push_str(": ");
            line.push_str(&text);
        }
        next = cause.source();
    }
    line
}

/// Whether pgrf's error `e` itself (not its causes) says a file could not
/// be read or written. pgrf's errors carry the operating system's error in
/// their message rather than as a source (so chains print it once), and
/// some wrap another crate's error transparently: both are looked through
/// here.
fn is_io_error(e: &(dyn Error + 'static)) -> bool {
    use pgrf_calib::mix::MixError;
    use pgrf_calib::synth::SynthError;
    use pgrf_calib::CalibError;
    use pgrf_raw::RawError;
    let raw = |r: &RawError| matches!(r, RawError::Io { .. });
    let calib = |c: &CalibError| match c {
        CalibError::Raw(r) | CalibError::Master { error: r, .. } => raw(r),
        CalibError::Read { .. } => true,
        _ => false,
    };
    let mix = |m: &MixError| matches!(m, MixError::Load(c) if calib(c));
    if e.is::<std::io::Error>() {
        return true;
    }
    if let Some(r) = e.downcast_ref::<RawError>() {
        return raw(r);
    }
    if let Some(c) = e.downcast_ref::<CalibError>() {
        return calib(c);
    }
    if let Some(m) = e.downcast_ref::<MixError>() {
        return mix(m);
    }
    match e.downcast_ref::<SynthError>() {
        Some(SynthError::Raw(r)) => raw(r),
        Some(SynthError::Calibration(m)) => mix(m),
        _ => false,
    }
}

/// Whether the error or one of its causes is a failed file operation.
fn is_io(e: &(dyn Error + 'static)) -> bool {
    let mut next: Option<&(dyn Error + 'static)> = Some(e);
    while let Some(err) = next {
        if is_io_error(err) {
            return true;
        }
        next = err.source();
    }
    false
}

/// `e` as the Python exception a caller can act on.
pub fn to_py<E: Error + 'static>(e: E) -> PyErr {
    let line = chain(&e);
    if is_io(&e) {
        PyOSError::new_err(line)
    } else {
        PyValueError::new_err(line)
    }
}

/// A refused argument, with pgrf's wording.
pub fn bad(message: impl Into<String>) -> PyErr {
    PyValueError::new_err(message.into())
}
