//! Restoring one dark RAW frame: the one path that `pgrf enhance`, `pgrf
//! demo` and `pgrf eval` share, from the decoded capture (or an already
//! packed input) through the tiled network to the result in the input's own
//! mosaic and levels.

use super::image::{
    check_tiling_args, frame_plan, overlap_for, restore_image, round_tile, ImageOptions,
};
use super::memory::auto_tile;
use super::prepare::network_input;
use super::restorer::Restore;
use super::tiles::TilePlan;
use crate::backend::DeviceKind;
use crate::condition::NoiseLevel;
use crate::error::{NnError, Result};
use ndarray::{Array3, ArrayView3};
use pgrf_core::Progress;
use pgrf_raw::{unpack_normalized, RawFrame};

/// How a frame is cut into tiles; `None` lets pgrf decide (tile from the
/// device's free memory and the model's cap, overlap from the tile).
#[derive(Clone, Copy, Debug)]
pub struct Tiling {
    /// Tile side in packed pixels.
    pub tile: Option<usize>,
    /// Minimum overlap between tiles in packed pixels.
    pub overlap: Option<usize>,
    /// Seed of the flow model's start noise X0.
    pub seed: u64,
    /// Where the network runs (the automatic tile depends on it).
    pub device: DeviceKind,
    /// Whose CPU operations the network runs ([`crate::ops::Kernels`]).
    pub kernels: crate::ops::Kernels,
}

impl Tiling {
    /// The concrete tiling of a `(4, ph, pw)` input for `r`.
    pub(crate) fn options(&self, r: &dyn Restore, ph: usize, pw: usize) -> ImageOptions {
        let tile = self
            .tile
            .unwrap_or_else(|| auto_tile(self.device, r, ph, pw));
        ImageOptions {
            tile,
            // The default overlap follows the tile as it will run (rounded
            // to the network's multiple), so any tile of 2x that is accepted.
            overlap: self.overlap.unwrap_or_else(|| {
                overlap_for(round_tile(tile, ph.max(pw), r.side_multiple().max(1)))
            }),
            seed: self.seed,
            noise: None,
        }
    }
}

/// A restored packed input and the tiles it took.
pub struct RestoredPacked {
    /// The restored planes in [0, 1], shaped like the input.
    pub output: Array3<f32>,
    /// The tiles that were run.
    pub plan: TilePlan,
}

impl RestoredPacked {
    /// The side of the largest tile, for reports.
    pub fn tile_side(&self) -> usize {
        self.plan.rows.len.max(self.plan.cols.len)
    }
}

/// Restore a packed, amplified network input `(4, h, w)` in [0, 1] (as
/// [`crate::infer::prepare::network_input`] makes it) with `r`, tiled as
/// `tiling` says; `noise` is the input's noise level (needed by a
/// conditioned network). `progress` hears one `start(tiles, "tiles")` and
/// one `advance` per tile.
pub fn restore_packed(
    r: &dyn Restore,
    input: ArrayView3<f32>,
    noise: Option<NoiseLevel>,
    tiling: &Tiling,
    progress: &dyn Progress,
) -> Result<RestoredPacked> {
    let (_, ph, pw) = input.dim();
    check_tiling_args(tiling.tile, tiling.overlap)?;
    let opts = ImageOptions {
        noise,
        ..tiling.options(r, ph, pw)
    };
    let plan = frame_plan(r, ph, pw, &opts)?;
    if tiling.tile.is_some() && tiling.device == DeviceKind::Cpu {
        // A tile the user chose is checked against the memory there is
        // (the automatic one is sized from it).
        let need = super::memory::windowed_tile_bytes(
            &r.meta().arch,
            plan.rows.len,
            plan.cols.len,
            r.window(),
        ) + super::memory::fixed_bytes(r, ph, pw) as f64;
        pgrf_core::mem::check_fits(&format!("--tile {}", opts.tile), need).map_err(|e| {
            NnError::TooLarge(format!(
                "{e}; leave --tile out (pgrf would use {}) or give a smaller one",
                auto_tile(DeviceKind::Cpu, r, ph, pw)
            ))
        })?;
    }
    progress.start(plan.count() as u64, "tiles");
    let output =
        crate::ops::with_kernels(tiling.kernels, || restore_image(r, input, &opts, progress))?;
    progress.finish();
    Ok(RestoredPacked { output, plan })
}

/// A restored frame: the result in the input's mosaic, with what was fed to
/// the network and what came out (both packed), for scoring.
pub struct RestoredFrame {
    /// The packed, amplified network input.
    pub input: Array3<f32>,
    /// The packed network output and its tiles.
    pub packed: RestoredPacked,
    /// The result unpacked to the input frame's size, CFA and levels.
    pub frame: RawFrame,
}

/// Restore a dark capture `frame` brightened by `ratio` (the exposure
/// ratio, positive), after subtracting `dark_dn` (a calibration's dark
/// shading in DN above black, packed like the frame), with `r`, tiled as
/// `tiling` says; `noise` is the brightened input's noise level (needed by
/// a conditioned network). `progress` hears the tiles as in
/// [`restore_packed`].
pub fn restore_frame(
    r: &dyn Restore,
    frame: &RawFrame,
    ratio: f32,
    dark_dn: Option<&Array3<f32>>,
    noise: Option<NoiseLevel>,
    tiling: &Tiling,
    progress: &dyn Progress,
) -> Result<RestoredFrame> {
    let input = network_input(frame, ratio, dark_dn)?;
    let packed = restore_packed(r, input.view(), noise, tiling, progress)?;
    let frame = unpack_normalized(packed.output.view(), frame)?;
    Ok(RestoredFrame {
        input,
        packed,
        frame,
    })
}
