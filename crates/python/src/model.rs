//! `pgrf.Model`: a built-in or trained network (SPC denoiser or PGRF flow
//! model) restoring packed numpy arrays, as `pgrf enhance` restores files
//! (pgrf-app's [`pgrf_app::array`]): loaded once, then called from any
//! thread with the GIL released.

use crate::errors::{bad, chain, to_py};
use crate::frame::{frame_of_meta, with_pixels};
use crate::threads::run;
use numpy::{IntoPyArray, PyArray3, PyReadonlyArray3};
use pgrf_app::array::{array_level, restore_array, ArrayNoise};
use pgrf_app::builtin::load_model;
use pgrf_nn::backend::DeviceKind;
use pgrf_nn::flow::sample::SamplerKind;
use pgrf_nn::infer::{check_tiling_args, Restore, SamplerChoice, Tiling};
use pgrf_raw::unpack_normalized;
use pyo3::exceptions::PyOSError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// A loaded network (opaque; `pgrf.Model` wraps it).
#[pyclass(frozen, module = "pgrf._pgrf")]
pub struct Network {
    restorer: Box<dyn Restore>,
    device: DeviceKind,
}

/// A parsed argument, refused with the argument's name.
fn parse<T: std::str::FromStr>(what: &str, text: &str) -> PyResult<T>
where
    T::Err: std::fmt::Display,
{
    text.parse().map_err(|e| bad(format!("{what}: {e}")))
}

#[pymethods]
impl Network {
    /// load(spec, sampler="two-stage", t2=None, samples=1, device="cpu")
    ///
    /// `spec`: "builtin:spc", "builtin:pgrf" or a weight file.
    #[staticmethod]
    #[pyo3(signature = (spec, sampler="two-stage", t2=None, samples=1, device="cpu"))]
    fn load(
        py: Python<'_>,
        spec: PathBuf,
        sampler: &str,
        t2: Option<f32>,
        samples: usize,
        device: &str,
    ) -> PyResult<Network> {
        let choice = SamplerChoice {
            kind: parse::<SamplerKind>("sampler", sampler)?,
            t2,
            samples,
        };
        let device: DeviceKind = parse("device", device)?;
        device.check_available().map_err(to_py)?;
        let name = spec.display().to_string();
        if !name.starts_with("builtin:") {
            std::fs::metadata(&spec).map_err(|e| PyOSError::new_err(format!("{name}: {e}")))?;
        }
        let restorer = py
            .detach(|| load_model(&spec, choice, device))
            .map_err(|e| {
                let line = chain(&e);
                bad(match line.contains(&name) {
                    true => line,
                    false => format!("{name}: {line}"),
                })
            })?;
        Ok(Network { restorer, device })
    }

    /// The network and its sampler in one phrase, as `pgrf enhance` prints it.
    #[getter]
    fn description(&self) -> String {
        pgrf_app::enhance::describe_method(self.restorer.as_ref())
    }

    /// "spc" or "pgrf".
    #[getter]
    fn method(&self) -> &'static str {
        self.restorer.meta().arch.method().name()
    }

    /// Whether the network is told its input's noise level.
    #[getter]
    fn noise_aware(&self) -> bool {
        self.restorer.meta().arch.conditioning().needs_level()
    }

    /// Network evaluations per tile.
    #[getter]
    fn nfe(&self) -> usize {
        self.restorer.nfe()
    }

    /// The weight file's record as JSON.
    #[getter]
    fn record_json(&self) -> PyResult<String> {
        serde_json::to_string(self.restorer.meta()).map_err(to_py)
    }

    /// restore(packed, ratio, noise=None, meta=None, tile=None, overlap=None, seed=0)
    /// -> (ndarray, str | None)
    ///
    /// The low-level call behind `pgrf.Model.restore` (which documents it);
    /// also returns the noise found when it was looked up from `meta`.
    #[pyo3(signature = (packed, ratio, noise=None, meta=None, tile=None, overlap=None, seed=0))]
    #[allow(clippy::too_many_arguments)]
    fn restore<'py>(
        &self,
        py: Python<'py>,
        packed: PyReadonlyArray3<'py, f32>,
        ratio: f32,
        noise: Option<(f64, f64)>,
        meta: Option<&Bound<'py, PyDict>>,
        tile: Option<usize>,
        overlap: Option<usize>,
        seed: u64,
    ) -> PyResult<(Bound<'py, PyArray3<f32>>, Option<String>)> {
        let view = packed.as_array();
        check_tiling_args(tile, overlap).map_err(to_py)?;
        let template = match (meta, noise) {
            (Some(m), None) => Some(with_pixels(frame_of_meta(m)?, view.shape(), "packed")?),
            _ => None,
        };
        let tiling = Tiling {
            tile,
            overlap,
            seed,
            device: self.device,
            kernels: Default::default(),
        };
        let r = self.restorer.as_ref();
        let input = view.to_owned();
        let (out, found) = run(py, move || {
            let frame = template
                .map(|t| unpack_normalized(input.view(), &t))
                .transpose()
                .map_err(|e| pgrf_app::array::ArrayError::Network(e.into()))?;
            let source = match (&frame, noise) {
                (_, Some((s, o))) => ArrayNoise::Profile { s, o },
                (Some(f), None) => ArrayNoise::Lookup(f),
                (None, None) => ArrayNoise::Unknown,
            };
            let (level, found) = array_level(r, source, ratio)?;
            let out = restore_array(r, input, ratio, level, &tiling)?;
            Ok::<_, pgrf_app::array::ArrayError>((out, found.map(|n| n.to_string())))
        })?;
        Ok((out.into_pyarray(py), found))
    }
}
