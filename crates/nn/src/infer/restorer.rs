//! A loaded network ready to restore packed tiles, whichever it is (the SPC
//! denoiser in one pass, the flow model through its sampler) and wherever it
//! runs. Commands hold it as `Box<dyn Restore>` so that they are not generic
//! over burn's backends.

use crate::arch::Net;
use crate::backend::{on_device, DeviceKind, OnBackend};
use crate::condition::NoiseLevel;
use crate::error::{NnError, Result};
use crate::flow::sample::{Sampler, SamplerKind};
use crate::ops::PgrfOps;
use crate::weights::{self, WeightMeta};
use burn::tensor::backend::Backend;
use burn::tensor::{Tensor, TensorData};
use ndarray::{Array3, ArrayView3};

/// The most flow samples averaged (`--samples`, in enhance and in the
/// search's averaging study); each holds a start field of the whole frame,
/// and every sample costs a full two-stage pass.
pub const MAX_SAMPLES: usize = 64;
use std::path::Path;

/// t2 used when a flow model's file has not been through `pgrf search`.
pub const UNSEARCHED_T2: f32 = 0.5;

/// How the user asked the flow model to be sampled.
#[derive(Clone, Copy, Debug)]
pub struct SamplerChoice {
    /// Which sampler (default: the two-stage one).
    pub kind: SamplerKind,
    /// Overrides the file's searched t2.
    pub t2: Option<f32>,
    /// Samples with different X0 averaged per image (K >= 1).
    pub samples: usize,
}

impl Default for SamplerChoice {
    fn default() -> Self {
        SamplerChoice {
            kind: SamplerKind::TwoStage,
            t2: None,
            samples: 1,
        }
    }
}

/// Restores packed `(4, h, w)` tiles of amplified noisy raw in [0, 1].
/// Implemented by [`Restorer`] on every backend; [`load`] gives one as a
/// `Box<dyn Restore>`.
pub trait Restore: Send + Sync {
    /// The weight file's record (architecture, noise, training, t2).
    fn meta(&self) -> &WeightMeta;
    /// The flow model's sampler; None for the one-pass denoiser.
    fn sampler(&self) -> Option<Sampler>;
    /// Start fields averaged per image (0 for the denoiser).
    fn samples(&self) -> usize;
    /// Sides of tiles should be multiples of this (no internal padding).
    fn side_multiple(&self) -> usize;
    /// Side of the windows a flow network takes its statistics over (0:
    /// each tile whole): frames are padded to whole windows and tiled on
    /// their grid ([`crate::infer::image::restore_image`]).
    fn window(&self) -> usize {
        0
    }
    /// The restored tile, `(4, h, w)` like `input` and not clamped, from
    /// `input` (T, packed, amplified, in [0, 1]) and one X0 per sample
    /// (none for the denoiser), each of `input`'s shape; the flow model's
    /// samples are averaged. `level` is the input's noise level, which a
    /// conditioned network needs ([`crate::condition`]) and an
    /// unconditioned one ignores.
    fn restore(
        &self,
        input: ArrayView3<f32>,
        x0s: &[ArrayView3<f32>],
        level: Option<NoiseLevel>,
    ) -> Result<Array3<f32>>;

    /// Bytes the network's parameters occupy.
    fn weight_bytes(&self) -> u64;

    /// Network evaluations per image.
    fn nfe(&self) -> usize {
        self.sampler().map_or(1, |s| s.nfe() * self.samples())
    }
}

/// The sampler in words for headers: "one pass" for the denoiser, else the
/// sampler, where t2 came from, the samples averaged and the network
/// evaluations per image.
pub fn describe_sampler(r: &dyn Restore) -> String {
    match r.sampler() {
        None => "one pass".into(),
        Some(s) => {
            let src = match (s, r.meta().t2) {
                (Sampler::TwoStage { .. }, Some(_)) => ", t2 from the file's search",
                (Sampler::TwoStage { .. }, None) => ", t2 not searched: default",
                _ => "",
            };
            let k = if r.samples() > 1 {
                format!(", mean of {} samples", r.samples())
            } else {
                String::new()
            };
            format!("{s}{src}{k}, {} network evaluations", r.nfe())
        }
    }
}

/// A network on backend `B` with its record and sampler, ready to restore
/// tiles ([`Restore`]).
pub struct Restorer<B: Backend> {
    net: Net<B>,
    meta: WeightMeta,
    sampler: Sampler,
    samples: usize,
    device: B::Device,
}

impl<B: PgrfOps> Restorer<B> {
    /// Build from a weight file's bytes; `path` names them in errors.
    pub(crate) fn load_bytes(
        path: &Path,
        bytes: &[u8],
        choice: SamplerChoice,
        device: B::Device,
    ) -> Result<Self> {
        let (net, meta) = crate::model::load_bytes::<B>(path, bytes, &device)?;
        let t2 = choice.t2.or(meta.t2).unwrap_or(UNSEARCHED_T2);
        Self::new(net, meta, choice, t2, device)
    }

    /// Wrap `net` (described by `meta`) on `device`, sampling the flow model
    /// as `choice` says with second time `t2` for the two-stage sampler
    /// (callers resolve it: `choice.t2`, else the file's, else
    /// [`UNSEARCHED_T2`]). Refuses `t2` outside [0, 1] and zero samples.
    pub fn new(
        net: Net<B>,
        meta: WeightMeta,
        choice: SamplerChoice,
        t2: f32,
        device: B::Device,
    ) -> Result<Self> {
        if !(0.0..=1.0).contains(&t2) {
            return Err(NnError::BadSetting {
                flag: "--t2",
                message: format!("t2 must be in [0, 1], got {t2}"),
            });
        }
        if !(1..=MAX_SAMPLES).contains(&choice.samples) {
            return Err(NnError::BadSetting {
                flag: "--samples",
                message: format!(
                    "--samples must be from 1 to {MAX_SAMPLES}, got {}",
                    choice.samples
                ),
            });
        }
        let sampler = match choice.kind {
            SamplerKind::TwoStage => Sampler::TwoStage { t2 },
            SamplerKind::OneStep => Sampler::OneStep,
            SamplerKind::Euler(steps) => Sampler::Euler { steps },
        };
        let net = net
            .with_window(trained_window(&meta))
            .map_err(|e| NnError::Invalid(e.to_string()))?;
        Ok(Restorer {
            net,
            meta,
            sampler,
            samples: choice.samples,
            device,
        })
    }

    /// The restorer with the flow network's statistics taken over windows
    /// of `side` (0: each tile whole, as before windows existed) instead of
    /// the training crop's; for comparisons. Refuses a side that is not a
    /// multiple of the network's.
    pub fn with_window(mut self, side: usize) -> Result<Self> {
        self.net = self
            .net
            .with_window(side)
            .map_err(|e| NnError::BadSetting {
                flag: "--window",
                message: e.to_string(),
            })?;
        Ok(self)
    }

    fn tensor(&self, a: ArrayView3<f32>) -> Tensor<B, 4> {
        let (c, h, w) = a.dim();
        let v: Vec<f32> = a.iter().copied().collect();
        Tensor::from_data(TensorData::new(v, [1, c, h, w]), &self.device)
    }
}

impl<B: PgrfOps> Restore for Restorer<B> {
    fn meta(&self) -> &WeightMeta {
        &self.meta
    }

    fn sampler(&self) -> Option<Sampler> {
        self.net.sampled().then_some(self.sampler)
    }

    fn samples(&self) -> usize {
        if self.net.sampled() {
            self.samples
        } else {
            0
        }
    }

    fn weight_bytes(&self) -> u64 {
        use burn::module::Module;
        4 * self.net.num_params() as u64
    }

    fn side_multiple(&self) -> usize {
        match self.net.window() {
            0 => self.meta.arch.side_multiple(),
            w => w,
        }
    }

    fn window(&self) -> usize {
        self.net.window()
    }

    fn restore(
        &self,
        input: ArrayView3<f32>,
        x0s: &[ArrayView3<f32>],
        level: Option<NoiseLevel>,
    ) -> Result<Array3<f32>> {
        let (c, h, w) = input.dim();
        let conditioning = self.meta.arch.conditioning();
        if conditioning.needs_level() {
            match level {
                Some(l) if l.is_usable() => {}
                Some(l) => {
                    return Err(NnError::BadNoiseLevel {
                        gain: l.gain,
                        floor: l.floor,
                    })
                }
                None => {
                    return Err(NnError::NoNoiseLevel {
                        conditioning: conditioning.name(),
                    })
                }
            }
        }
        if c != 4 {
            return Err(NnError::SizeMismatch(format!(
                "the networks take 4 packed planes, got {c}"
            )));
        }
        let cond = self.tensor(input);
        if self.net.sampled() {
            if x0s.len() != self.samples {
                return Err(NnError::SizeMismatch(format!(
                    "{} start fields for {} samples",
                    x0s.len(),
                    self.samples
                )));
            }
            for x0 in x0s {
                if x0.dim() != (c, h, w) {
                    return Err(NnError::SizeMismatch("X0 and input differ in shape".into()));
                }
            }
        }
        let out = self.net.restore_tile(
            cond,
            level,
            x0s.len(),
            |k| self.tensor(x0s[k]),
            self.sampler,
        );
        let v: Vec<f32> = out
            .into_data()
            .to_vec()
            .map_err(|e| NnError::Invalid(format!("reading the network output: {e:?}")))?;
        Array3::from_shape_vec((c, h, w), v)
            .map_err(|e| NnError::SizeMismatch(format!("network output shape: {e}")))
    }
}

/// The window a flow network restores with: the window it was trained
/// with (`pgrf train --window`), else the side of the crops its file says
/// it was trained on (each crop was one window, so every window of a frame
/// sees what a crop did), when that is a multiple of the network's side
/// multiple; else 0 (whole tiles), as for a file without a training record.
/// The denoiser has none.
fn trained_window(meta: &WeightMeta) -> usize {
    let m = meta.arch.side_multiple().max(1);
    let Some(t) = meta.training.as_ref().filter(|_| meta.arch.sampled()) else {
        return 0;
    };
    let side = t.config.as_ref().and_then(|c| c.window).unwrap_or(t.patch);
    if side >= m && side.is_multiple_of(m) {
        side
    } else {
        0
    }
}

/// Load the weight file at `path` on `device`, sampled as `choice` says
/// (t2: `choice.t2`, else the file's searched one, else [`UNSEARCHED_T2`]).
/// Refuses `cuda` in a build without it.
pub fn load(path: &Path, choice: SamplerChoice, device: DeviceKind) -> Result<Box<dyn Restore>> {
    load_bytes(path, &weights::read_bytes(path)?, choice, device)
}

/// [`load`] from a weight file's bytes (weights built into the binary);
/// `path` names them in errors.
pub fn load_bytes(
    path: &Path,
    bytes: &[u8],
    choice: SamplerChoice,
    device: DeviceKind,
) -> Result<Box<dyn Restore>> {
    struct Job<'a> {
        path: &'a Path,
        bytes: &'a [u8],
        choice: SamplerChoice,
    }
    impl OnBackend for Job<'_> {
        type Output = Box<dyn Restore>;
        fn run<B: PgrfOps>(self, device: B::Device) -> Result<Box<dyn Restore>> {
            Ok(Box::new(Restorer::<B>::load_bytes(
                self.path,
                self.bytes,
                self.choice,
                device,
            )?))
        }
    }
    on_device(
        device,
        Job {
            path,
            bytes,
            choice,
        },
    )
}
