//! `pgrf.unprocess`: an ordinary sRGB photo into a camera's RAW space
//! (Brooks et al.'s unprocessing, pgrf-scenes'), packed like a decoded RAW,
//! so clean training images come from photos as `pgrf train` makes them.

use crate::errors::{bad, to_py};
use crate::frame::frame_of_meta;
use crate::threads::run;
use numpy::{IntoPyArray, PyArray3, PyReadonlyArray3};
use pgrf_scenes::photo::Photo;
use pgrf_scenes::unprocess::{unprocess_window, CameraSpace, EncodedPhoto, Unprocessing};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// The camera named by `camera`: "sony-a7s2" (the built-in profile's
/// camera) or a frame's metadata (its colour matrix, white balance, CFA
/// and levels).
fn camera_space(camera: &Bound<'_, PyAny>) -> PyResult<CameraSpace> {
    if let Ok(name) = camera.extract::<String>() {
        return match name.as_str() {
            "sony-a7s2" => Ok(CameraSpace::sony_a7s2()),
            other => Err(bad(format!(
                "unprocess camera {other:?}: the built-in camera space is \"sony-a7s2\"; pass a RAW's Metadata for another camera"
            ))),
        };
    }
    let d = camera
        .cast::<PyDict>()
        .map_err(|_| bad("unprocess camera: a name or a Metadata's fields"))?;
    let frame = frame_of_meta(d)?;
    if frame.mono {
        return Err(bad(
            "unprocess camera: a monochrome sensor has no colour to unprocess into",
        ));
    }
    CameraSpace::of(&frame).map_err(to_py)
}

/// unprocess(photo, camera, seed=None, exposure=1.0, wb_spread=1.25) -> ndarray
///
/// The low-level call behind `pgrf.unprocess` (which documents it).
#[pyfunction]
#[pyo3(signature = (photo, camera, seed=None, exposure=1.0, wb_spread=pgrf_scenes::unprocess::WB_SPREAD))]
pub fn unprocess<'py>(
    py: Python<'py>,
    photo: PyReadonlyArray3<'py, f32>,
    camera: &Bound<'py, PyAny>,
    seed: Option<u64>,
    exposure: f32,
    wb_spread: f32,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let cam = camera_space(camera)?;
    let v = photo.as_array();
    let (h, w, c) = v.dim();
    if c != 3 || h < 2 || w < 2 {
        return Err(bad(format!(
            "unprocess: expected an sRGB photo of shape (H, W, 3) with H, W >= 2, got {:?}",
            v.shape()
        )));
    }
    if !(wb_spread.is_finite() && wb_spread >= 1.0) {
        return Err(bad(format!(
            "unprocess: wb_spread must be >= 1, got {wb_spread}"
        )));
    }
    let plain = Unprocessing::plain(&cam, exposure).map_err(to_py)?;
    let u = match seed {
        Some(s) => plain.jittered(s, wb_spread),
        None => plain,
    };
    let out = run(py, || {
        let photo = Photo {
            width: w,
            height: h,
            rgb: v.iter().copied().collect(),
        };
        let enc = EncodedPhoto::from_photo(&photo);
        unprocess_window(&enc, (0, 0), (h / 2, w / 2), &cam, &u)
    })?;
    Ok(out.into_pyarray(py))
}
