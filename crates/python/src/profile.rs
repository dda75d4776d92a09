//! `pgrf.Profile`: the camera whose noise `synth` simulates. A built-in
//! profile, a camera of darktable's noiseprofiles.json, a DNG's
//! NoiseProfile tag, a profile JSON file, or a per-pixel calibration from
//! `pgrf calibrate` on top of a base profile: the same sources as the
//! command's `--profile` and `--calib`, loaded by the same code.

use crate::errors::to_py;
use pgrf_calib::mix::CalibrationFile;
use pgrf_noise::CameraProfile;
use pyo3::prelude::*;
use std::path::PathBuf;
use std::sync::Arc;

/// A camera's noise: a profile, and for the PGRF model optionally a
/// per-pixel calibration. Make one with the static methods.
#[pyclass(frozen, module = "pgrf._pgrf")]
#[derive(Clone)]
pub struct Profile {
    /// What `--profile` would say for it (for repr and messages).
    pub(crate) spec: String,
    pub(crate) profile: CameraProfile,
    pub(crate) calibration: Option<Arc<CalibrationFile>>,
}

/// The profile `spec` names; `darktable` names darktable's file for a
/// `darktable:` spec (None: darktable's install is searched).
fn load(spec: String, darktable: Option<&std::path::Path>) -> PyResult<Profile> {
    let profile = CameraProfile::load(&spec, darktable).map_err(to_py)?;
    Ok(Profile {
        spec,
        profile,
        calibration: None,
    })
}

#[pymethods]
impl Profile {
    /// Profile.builtin(name) -> Profile
    ///
    /// A built-in profile (Profile.names() lists them).
    #[staticmethod]
    fn builtin(name: &str) -> PyResult<Profile> {
        match CameraProfile::built_in(name) {
            Some(profile) => Ok(Profile {
                spec: name.to_string(),
                profile,
                calibration: None,
            }),
            None => Err(crate::errors::bad(format!(
                "no built-in profile {name:?} (built-in: {})",
                pgrf_noise::profile::built_in_names().join(", ")
            ))),
        }
    }

    /// Profile.load(spec) -> Profile
    ///
    /// What the command's --profile takes: a built-in name,
    /// "darktable:MAKER MODEL", "dng:FILE.dng" or a profile JSON file.
    #[staticmethod]
    fn load(spec: &str) -> PyResult<Profile> {
        load(spec.to_string(), None)
    }

    /// Profile.names() -> list[str]
    ///
    /// The built-in profiles' names.
    #[staticmethod]
    fn names() -> Vec<&'static str> {
        pgrf_noise::profile::built_in_names()
    }

    /// Profile.darktable(maker_model, path=None) -> Profile
    ///
    /// A camera of darktable's noiseprofiles.json, e.g. "Canon EOS 550D";
    /// `path` names the file (as the CLI's --darktable-profiles; else
    /// darktable's install is searched).
    #[staticmethod]
    #[pyo3(signature = (maker_model, path=None))]
    fn darktable(maker_model: &str, path: Option<PathBuf>) -> PyResult<Profile> {
        load(format!("darktable:{maker_model}"), path.as_deref())
    }

    /// Profile.dng(path) -> Profile
    ///
    /// The NoiseProfile tag of a DNG, at its ISO.
    #[staticmethod]
    fn dng(path: PathBuf) -> PyResult<Profile> {
        load(format!("dng:{}", path.display()), None)
    }

    /// Profile.json(path) -> Profile
    ///
    /// A profile JSON file (the keys of pgrf's built-in profiles).
    #[staticmethod]
    fn json(path: PathBuf) -> PyResult<Profile> {
        let spec = path.display().to_string();
        if CameraProfile::built_in(&spec).is_some() {
            return Err(crate::errors::bad(format!(
                "{spec:?} is a built-in profile's name; use Profile.builtin"
            )));
        }
        load(spec, None)
    }

    /// Profile.calibration(path, base="sony-a7s2") -> Profile
    ///
    /// A per-pixel calibration file from `pgrf calibrate` (for
    /// model="pgrf"): its maps, gain and row noise replace the base
    /// profile's; the base supplies only what a calibration does not
    /// measure (the parameter fits used when no ISO is set), as `pgrf synth
    /// --profile BASE --calib FILE`.
    #[staticmethod]
    #[pyo3(signature = (path, base="sony-a7s2"))]
    fn calibration(py: Python<'_>, path: PathBuf, base: &str) -> PyResult<Profile> {
        let mut p = load(base.to_string(), None)?;
        let file = crate::threads::run(py, || CalibrationFile::load(&path, None, None))?;
        p.spec = format!("{base} + calibration {}", path.display());
        p.calibration = Some(Arc::new(file));
        Ok(p)
    }

    /// The camera's maker and model as the profile names them.
    #[getter]
    fn camera(&self) -> String {
        let v = pgrf_noise::pg_profile::view(&self.profile);
        format!("{} {}", v.make, v.model)
    }

    /// white - black of the profile's camera, DN: the scale a normalised
    /// value 1 stands for in synthesis (noise figures are in these DN).
    #[getter]
    fn dn_range(&self) -> f64 {
        self.profile.dn_range()
    }

    /// Whether a per-pixel calibration is attached.
    #[getter]
    fn calibrated(&self) -> bool {
        self.calibration.is_some()
    }

    fn __repr__(&self) -> String {
        format!("pgrf.Profile({})", self.spec)
    }
}
