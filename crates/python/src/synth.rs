//! `pgrf.synth` and `pgrf.synth_batch`: a simulated low-light capture of a
//! packed clean image, by `pgrf_calib::synth::synthesize_packed`, the recipe
//! `pgrf synth` runs, so the same image, settings and seed give the same
//! numbers in Python as on the command line.

use crate::errors::bad;
use crate::frame::{check_packed, frame_of_meta, meta_dict};
use crate::profile::Profile;
use crate::threads::run;
use ndarray::{Array3, Array4, ArrayView3, Axis};
use numpy::{IntoPyArray, PyArray3, PyArray4, PyReadonlyArray3, PyReadonlyArray4};
use pgrf_calib::synth::{
    synthesize_packed, with_dark_rate, CleanFacts, PackedCapture, SynthConfig,
};
use pgrf_core::parse::ParseError;
use pgrf_noise::{DarkLaw, ModelKind};
use pgrf_raw::{Cfa, RawFrame};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rayon::prelude::*;
use std::path::Path;

/// The settings every synth call shares (keyword arguments of `pgrf.synth`).
#[derive(Clone, Debug)]
struct Settings {
    ratio: Option<f32>,
    iso: Option<u32>,
    model: ModelKind,
    components: String,
    global: bool,
    gaussian_read: bool,
    exposure_s: Option<f32>,
    dark_rate: Option<f64>,
    dark_law: DarkLaw,
    noise_bank: bool,
}

impl Settings {
    fn config(&self, seed: u64) -> SynthConfig {
        SynthConfig {
            profile: String::new(),
            ratio: self.ratio,
            iso: self.iso,
            model: self.model,
            components: self.components.clone(),
            global: self.global,
            gaussian_read: self.gaussian_read,
            exposure_time: self.exposure_s,
            dark_rate: self.dark_rate,
            dark_law: self.dark_law,
            calib: None,
            force: false,
            seed,
            brightened: false,
            masked_columns: 0,
            darktable: None,
            noise_bank: self.noise_bank,
        }
    }
}

/// The clean image's facts: from the metadata's frame when given (its CFA, ISO and
/// exposure, as `pgrf synth` takes them from the file), else from `cfa`.
fn facts(frame: Option<&RawFrame>, cfa: Option<&str>) -> PyResult<CleanFacts> {
    if let Some(f) = frame {
        if cfa.is_some() {
            return Err(bad(
                "synth: give meta or cfa, not both (meta holds the CFA)",
            ));
        }
        return Ok(CleanFacts::of(f));
    }
    let cfa: Cfa = match cfa {
        None => Cfa::Rggb,
        Some(c) if c.eq_ignore_ascii_case("mono") => Cfa::Rggb,
        Some(c) => c
            .parse()
            .map_err(|e: ParseError| bad(format!("synth cfa: {e}")))?,
    };
    Ok(CleanFacts {
        plane_rows: cfa.offsets().map(|(r, _)| r),
        iso: None,
        exposure_s: None,
    })
}

/// Refuse an image no capture can be made of before any work.
fn check_clean(v: &ArrayView3<f32>, what: &str) -> PyResult<()> {
    let s = v.shape();
    if s[0] != 4 || s[1] == 0 || s[2] == 0 {
        return Err(bad(format!(
            "{what}: expected packed planes of shape (4, H/2, W/2), got {s:?}"
        )));
    }
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(bad(format!(
            "{what}: value {} at flat index {i} is not finite",
            v.iter().nth(i).copied().unwrap_or(f32::NAN)
        )));
    }
    Ok(())
}

/// One capture's numbers as the dict `pgrf.Capture` is built from.
fn info<'py>(py: Python<'py>, c: &PackedCapture) -> PyResult<Bound<'py, PyDict>> {
    let c = &c.info;
    let d = PyDict::new(py);
    d.set_item("ratio", c.ratio)?;
    d.set_item("exposure_s", c.exposure_s)?;
    d.set_item("iso", c.iso)?;
    d.set_item("components", c.components.to_string())?;
    d.set_item("k", c.k)?;
    d.set_item("read_dn", c.read_dn)?;
    d.set_item("row_dn", c.row_dn)?;
    Ok(d)
}

/// Key `key` of the settings dict, converted; `default` when absent or None.
fn setting<'py, T: pyo3::conversion::FromPyObjectOwned<'py>>(
    d: &Bound<'py, PyDict>,
    key: &str,
    default: T,
) -> PyResult<T> {
    match d.get_item(key)? {
        Some(v) if !v.is_none() => v.extract::<T>().map_err(|e| {
            let e: PyErr = e.into();
            bad(format!("synth {key}: {e}"))
        }),
        _ => Ok(default),
    }
}

/// The keyword arguments of `pgrf.synth` (a dict the Python side builds):
/// unknown keys, models and laws refused here; components and numbers out
/// of range by the recipe, before it draws anything
/// ([`synthesize_packed`]'s first checks).
fn parse_settings(d: &Bound<'_, PyDict>) -> PyResult<Settings> {
    const KEYS: [&str; 10] = [
        "ratio",
        "iso",
        "model",
        "components",
        "global_maps",
        "gaussian_read",
        "exposure_s",
        "dark_rate",
        "dark_law",
        "noise_bank",
    ];
    for k in d.keys() {
        let k: String = k.extract()?;
        if !KEYS.contains(&k.as_str()) {
            return Err(bad(format!(
                "synth: unknown setting {k:?} (known: {})",
                KEYS.join(", ")
            )));
        }
    }
    let model: String = setting(d, "model", "pgrf".to_string())?;
    let model: ModelKind = model
        .parse()
        .map_err(|e: ParseError| bad(format!("synth model: {e}")))?;
    let law: String = setting(d, "dark_law", "sqrt".to_string())?;
    let dark_law: DarkLaw = law
        .parse()
        .map_err(|e: ParseError| bad(format!("synth dark_law: {e}")))?;
    let components: String = setting(d, "components", "P,G,H,Q,F,A".to_string())?;
    Ok(Settings {
        ratio: setting(d, "ratio", None)?,
        iso: setting(d, "iso", None)?,
        model,
        components,
        global: setting(d, "global_maps", false)?,
        gaussian_read: setting(d, "gaussian_read", false)?,
        exposure_s: setting(d, "exposure_s", None)?,
        dark_rate: setting(d, "dark_rate", None)?,
        dark_law,
        noise_bank: setting(d, "noise_bank", false)?,
    })
}

/// One capture of `clean` with `profile` and `s`.
fn capture(
    clean: ArrayView3<f32>,
    facts: &CleanFacts,
    profile: &Profile,
    s: &Settings,
    seed: u64,
) -> Result<PackedCapture, pgrf_calib::synth::SynthError> {
    let c = s.config(seed);
    let mut p = profile.profile.clone();
    with_dark_rate(&mut p, &c);
    synthesize_packed(
        clean,
        facts,
        p,
        profile.calibration.as_deref(),
        &c,
        Path::new("clean image"),
    )
}

/// synth(clean, profile, seed, settings, meta=None, cfa=None)
/// -> (dark, brightened, info, dark_meta, brightened_meta)
///
/// The low-level call behind `pgrf.synth` (which documents it and its
/// settings).
#[pyfunction]
#[pyo3(signature = (clean, profile, seed, settings, meta=None, cfa=None))]
#[allow(clippy::type_complexity)]
pub fn synth<'py>(
    py: Python<'py>,
    clean: PyReadonlyArray3<'py, f32>,
    profile: &Profile,
    seed: u64,
    settings: &Bound<'py, PyDict>,
    meta: Option<&Bound<'py, PyDict>>,
    cfa: Option<&str>,
) -> PyResult<(
    Bound<'py, PyArray3<f32>>,
    Bound<'py, PyArray3<f32>>,
    Bound<'py, PyDict>,
    Option<Bound<'py, PyDict>>,
    Option<Bound<'py, PyDict>>,
)> {
    let s = parse_settings(settings)?;
    let view = clean.as_array();
    check_clean(&view, "synth clean")?;
    let template = meta.map(frame_of_meta).transpose()?;
    let facts = facts(template.as_ref(), cfa)?;
    if let Some(t) = &template {
        check_packed(t, view.shape(), "synth clean")?;
    }
    let (made, dark, bright) = run(py, || {
        let mut made = capture(view, &facts, profile, &s, seed)?;
        let (dark, bright) = made.take_forms();
        Ok::<_, pgrf_calib::synth::SynthError>((made, dark, bright))
    })?;
    let metas = match template {
        Some(mut t) => {
            let mut b = t.clone();
            made.stamp(&mut t, false);
            made.stamp(&mut b, true);
            (Some(meta_dict(py, t)?), Some(meta_dict(py, b)?))
        }
        None => (None, None),
    };
    Ok((
        dark.into_pyarray(py),
        bright.into_pyarray(py),
        info(py, &made)?,
        metas.0,
        metas.1,
    ))
}

/// synth_batch(clean, profile, seeds, settings, cfa=None)
/// -> (dark, brightened, infos)
///
/// The low-level call behind `pgrf.synth_batch`: item i is exactly
/// `synth(clean[i], profile, seeds[i], settings)`, items in parallel.
#[pyfunction]
#[pyo3(signature = (clean, profile, seeds, settings, cfa=None))]
#[allow(clippy::type_complexity)]
pub fn synth_batch<'py>(
    py: Python<'py>,
    clean: PyReadonlyArray4<'py, f32>,
    profile: &Profile,
    seeds: Vec<u64>,
    settings: &Bound<'py, PyDict>,
    cfa: Option<&str>,
) -> PyResult<(
    Bound<'py, PyArray4<f32>>,
    Bound<'py, PyArray4<f32>>,
    Vec<Bound<'py, PyDict>>,
)> {
    let s = parse_settings(settings)?;
    let facts = facts(None, cfa)?;
    let view = clean.as_array();
    if view.shape()[0] != seeds.len() {
        return Err(bad(format!(
            "synth_batch: {} images but {} seeds (one seed per image)",
            view.shape()[0],
            seeds.len()
        )));
    }
    for (i, item) in view.axis_iter(Axis(0)).enumerate() {
        check_clean(&item, &format!("synth_batch clean[{i}]"))?;
    }
    let (made, dark, bright) = run(py, || {
        let made = view
            .axis_iter(Axis(0))
            .into_par_iter()
            .zip(seeds.par_iter())
            .map(|(item, &seed)| capture(item, &facts, profile, &s, seed))
            .collect::<Result<Vec<_>, _>>()?;
        let stack = |f: &(dyn Fn(&PackedCapture) -> Array3<f32> + Sync)| -> Array4<f32> {
            let mut out = Array4::<f32>::zeros(view.raw_dim());
            out.axis_iter_mut(Axis(0))
                .into_par_iter()
                .zip(made.par_iter())
                .for_each(|(mut o, m)| o.assign(&f(m)));
            out
        };
        let (dark, bright) = rayon::join(|| stack(&|m| m.dark()), || stack(&|m| m.brightened()));
        Ok::<_, pgrf_calib::synth::SynthError>((made, dark, bright))
    })?;
    let infos = made
        .iter()
        .map(|m| info(py, m))
        .collect::<PyResult<Vec<_>>>()?;
    Ok((dark.into_pyarray(py), bright.into_pyarray(py), infos))
}
