//! The exponential moving average of a network's weights during training
//! (`pgrf train --ema DECAY`): after every optimiser step each parameter of
//! the average moves a fraction `1 - d` of the way to the trained one. The
//! average smooths out the last steps' noise of small-batch Adam, which is
//! what a 2-core CPU run at batch 4 has most of; validation scores it
//! against the raw weights so the gain is measured, not assumed.
//!
//! The decay ramps up, `d = min(DECAY, (1 + step) / (10 + step))`, so a run
//! that starts from fresh weights does not drag their random start for
//! thousands of steps. The average is kept as named f32 tensors
//! ([`crate::named`]) on the host: updating 2 M parameters costs a few
//! milliseconds against a step's second, and checkpoints hold it as a
//! safetensors block so that a resumed run continues it exactly.

use crate::arch::{is_prior, Architecture, Net};
use crate::error::{NnError, Result};
use crate::named::NamedTensor;
use burn::tensor::backend::Backend;
use std::collections::BTreeMap;

/// The record string of an average's safetensors block in a checkpoint.
const META: &str = "{\"ema\":true}";

/// The moving average of a network's parameters, by name.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Ema {
    decay: f32,
    tensors: BTreeMap<String, NamedTensor>,
}

impl Ema {
    /// An average that starts at `params` (the network before its first
    /// step), with the configured `decay`.
    pub(crate) fn start(decay: f32, params: BTreeMap<String, NamedTensor>) -> Ema {
        Ema {
            decay,
            tensors: params,
        }
    }

    /// The decay applied after step `step` (counted from 0): the ramp of
    /// the module documentation, capped at the configured decay.
    pub(crate) fn decay_at(&self, step: u64) -> f32 {
        let ramp = (1.0 + step as f64) / (10.0 + step as f64);
        (self.decay as f64).min(ramp) as f32
    }

    /// Move the average towards `params`, the weights after step `step`.
    /// Names and shapes are the network's own, so they match by
    /// construction; a mismatch is a bug and panics.
    pub(crate) fn update(&mut self, step: u64, params: &BTreeMap<String, NamedTensor>) {
        let d = self.decay_at(step);
        // A flow's frozen prior stays as loaded, bit for bit.
        for (name, avg) in self.tensors.iter_mut().filter(|(n, _)| !is_prior(n)) {
            let p = &params[name];
            assert_eq!(avg.shape, p.shape, "EMA of {name}: shape changed");
            for (a, &v) in avg.values.iter_mut().zip(&p.values) {
                *a = d * *a + (1.0 - d) * v;
            }
        }
    }

    /// The averaged weights as a network of `arch`.
    pub(crate) fn network<B: Backend>(
        &self,
        arch: &Architecture,
        device: &B::Device,
    ) -> Result<Net<B>> {
        arch.init::<B>(device)?
            .assign(&self.tensors, device)
            .map_err(|e| NnError::SizeMismatch(format!("moving average of the weights: {e}")))
    }

    /// The average as a checkpoint block (safetensors).
    pub(crate) fn to_bytes(&self) -> Result<Vec<u8>> {
        pgrf_core::record::encode(
            self.tensors
                .iter()
                .map(|(n, t)| (n.as_str(), t.shape.as_slice(), t.values.as_slice())),
            META,
        )
        .map_err(|e| NnError::Invalid(format!("moving average of the weights: {e}")))
    }

    /// The average a checkpoint block holds, continued with `decay`; `what`
    /// names the checkpoint in errors.
    pub(crate) fn from_bytes(decay: f32, bytes: &[u8], what: &std::path::Path) -> Result<Ema> {
        let record = pgrf_core::record::decode(bytes).map_err(|e| NnError::BadFile {
            path: what.to_path_buf(),
            reason: format!("moving average block: {e}"),
        })?;
        Ok(Ema {
            decay,
            tensors: record.tensors,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one(v: f32) -> BTreeMap<String, NamedTensor> {
        BTreeMap::from([(
            "w".to_string(),
            NamedTensor {
                shape: vec![2],
                values: vec![v, -v],
            },
        )])
    }

    /// The ramp, the cap, and the average of a constant target against its
    /// closed form: after steps 0..n towards 1 from 0, the average is
    /// 1 - prod(d_k).
    #[test]
    fn the_average_follows_its_closed_form_and_round_trips() {
        let mut e = Ema::start(0.999, one(0.0));
        assert_eq!(e.decay_at(0), 0.1);
        assert!((e.decay_at(90) - 0.91).abs() < 1e-6);
        assert_eq!(e.decay_at(1_000_000), 0.999);
        let mut keep = 1.0f64;
        for step in 0..500 {
            keep *= e.decay_at(step) as f64;
            e.update(step, &one(1.0));
        }
        let got = e.tensors["w"].values[0] as f64;
        assert!((got - (1.0 - keep)).abs() < 1e-5, "{got} vs {}", 1.0 - keep);
        assert_eq!(e.tensors["w"].values[1], -e.tensors["w"].values[0]);
        let bytes = e.to_bytes().unwrap();
        let back = Ema::from_bytes(0.999, &bytes, std::path::Path::new("c")).unwrap();
        assert_eq!(back, e);
        assert!(
            Ema::from_bytes(0.999, &bytes[..bytes.len() - 1], std::path::Path::new("c")).is_err()
        );
    }
}
