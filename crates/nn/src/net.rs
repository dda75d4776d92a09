//! One type for either network, so a single optimiser type, checkpoint
//! format and loader serve both methods (SPC and PGRF).

use crate::error::{NnError, Result};
use crate::ops::PgrfOps;
use crate::sr3::Sr3Unet;
use crate::unet::SidUnet;
use crate::weights::{self, Architecture, WeightMeta};
use burn::module::Module;
use burn::tensor::backend::Backend;
use burn::tensor::Tensor;

/// Either network, as one module so one optimiser type serves both. Made by
/// [`Architecture::init`] / [`Architecture::init_seeded`] or read from a
/// weight file by [`crate::weights::load`]; inference wraps it in an
/// [`crate::infer::Restorer`].
// Moved rarely (once per optimiser step, by value as burn requires); boxing
// would buy nothing and complicate the derived module.
#[allow(clippy::large_enum_variant)]
#[derive(Module, Debug)]
pub enum Net<B: Backend> {
    /// The SPC denoiser: one pass from the amplified noisy input to the clean
    /// image.
    Spc(SidUnet<B>),
    /// The PGRF velocity field v(Xt, T, t), sampled by [`crate::flow::sample`].
    Pgrf(Sr3Unet<B>),
}

impl Architecture {
    /// A freshly initialised network of this architecture.
    pub fn init<B: Backend>(&self, device: &B::Device) -> Result<Net<B>> {
        Ok(match self {
            Architecture::SidUnet(c) => {
                // Records come from files: refuse what pgrf's 4-plane
                // pipeline cannot run before building anything.
                if c.width == 0 || c.in_channels != 4 || c.out_channels != 4 {
                    return Err(NnError::Config(format!(
                        "the SID U-Net needs a width of at least 1 and 4 planes in and out (got width {}, {} in, {} out)",
                        c.width, c.in_channels, c.out_channels
                    )));
                }
                if c.residual && c.in_channels != c.out_channels {
                    return Err(NnError::Config(format!(
                        "a residual SID U-Net needs as many output channels as input ({} vs {})",
                        c.out_channels, c.in_channels
                    )));
                }
                Net::Spc(c.init(device))
            }
            Architecture::Sr3(c) => Net::Pgrf(c.init(device).map_err(NnError::Config)?),
        })
    }
}

impl Architecture {
    /// A network of this architecture with weights drawn from `seed`: the
    /// same seed gives the same weights whatever else the process is doing.
    pub fn init_seeded<B: Backend>(&self, device: &B::Device, seed: u64) -> Result<Net<B>> {
        crate::seeded::seeded::<B, _>(device, seed, || {
            self.init(device).map(crate::seeded::materialise)
        })
    }
}

impl<B: PgrfOps> Net<B> {
    /// The denoised batch: one pass for SPC, the two-stage sampler at `t2`
    /// for the flow model. `noisy` is T, `(n, 4, h, w)`; `x0` is X0, same
    /// shape (ignored by SPC).
    pub(crate) fn restore(&self, noisy: Tensor<B, 4>, x0: Tensor<B, 4>, t2: f32) -> Tensor<B, 4> {
        match self {
            Net::Spc(n) => n.forward(noisy),
            Net::Pgrf(n) => crate::flow::sample::two_stage(n, noisy, x0, t2),
        }
    }

    /// Write the parameters and `meta` as a weight file at `path`, atomically
    /// ([`crate::weights`]).
    pub fn save(&self, path: &std::path::Path, meta: &WeightMeta) -> Result<()> {
        match self {
            Net::Spc(n) => weights::save::<B, _>(path, n, meta),
            Net::Pgrf(n) => weights::save::<B, _>(path, n, meta),
        }
    }
}
