//! Tiling a packed image so that any frame fits in memory, and blending the
//! tiles back without seams.
//!
//! A network's output near a tile border is worse than inside (it sees
//! padding instead of the neighbourhood), and it differs between two tiles
//! that cover the same pixel. So each tile's weight is zero in a margin along
//! every border it shares with a neighbour, and the two tiles hand over with a
//! raised-cosine ramp centred in their overlap. Along each axis the weights of
//! all tiles sum to exactly one at every pixel (a partition of unity), so the
//! blend is a convex combination and a pixel covered by one tile is that
//! tile's output unchanged. A frame that fits in one tile is not tiled at all.

use crate::error::{NnError, Result};
use ndarray::{s, Array2, Array3, ArrayView3, Axis};

/// Tile positions along one axis and the handover ramps between them.
#[derive(Clone, Debug, PartialEq)]
pub struct AxisPlan {
    /// Start of each tile, in packed pixels, increasing; the first is 0 and
    /// the last tile ends flush with the axis.
    pub starts: Vec<usize>,
    /// Tile length (the whole axis when it fits in one tile).
    pub len: usize,
    /// For each pair of neighbours (i, i+1): where the ramp starts and its length.
    ramps: Vec<(usize, usize)>,
}

impl AxisPlan {
    /// Tiles of `tile` samples overlapping by at least `overlap`, the last one
    /// flush with the end; one tile if the axis fits.
    pub(crate) fn new(total: usize, tile: usize, overlap: usize) -> Result<AxisPlan> {
        if total == 0 {
            return Err(NnError::Invalid("cannot tile an empty image".into()));
        }
        if tile >= total {
            return Ok(AxisPlan {
                starts: vec![0],
                len: total,
                ramps: Vec::new(),
            });
        }
        // Up to half the tile: then the stride is at least the overlap, so
        // the handover ramps of successive neighbours never overlap and no
        // pixel is blended from more than two tiles.
        if overlap == 0 || 2 * overlap > tile {
            return Err(NnError::BadSetting {
                flag: "--overlap",
                message: format!(
                    "tile overlap {overlap} must be between 1 and half the tile ({tile})"
                ),
            });
        }
        let stride = tile - overlap;
        let mut starts = Vec::new();
        let mut p = 0;
        while p + tile < total {
            starts.push(p);
            p += stride;
        }
        starts.push(total - tile);
        let margin = overlap / 4;
        let ramp = (overlap - 2 * margin).max(1);
        let ramps = starts
            .windows(2)
            .map(|w| {
                // Overlap region [w[1], w[0] + tile), at least `overlap` long
                // (longer for the flush last tile); the ramp sits in its centre.
                let region = w[0] + tile - w[1];
                (w[1] + (region - ramp) / 2, ramp)
            })
            .collect();
        Ok(AxisPlan {
            starts,
            len: tile,
            ramps,
        })
    }

    /// Tiles along this axis.
    pub fn count(&self) -> usize {
        self.starts.len()
    }

    /// Weights of tile `i` along this axis (length `self.len`).
    pub(crate) fn weights(&self, i: usize) -> Vec<f32> {
        let start = self.starts[i];
        let mut w = vec![1.0f32; self.len];
        if i > 0 {
            let (r0, n) = self.ramps[i - 1];
            for (j, v) in w.iter_mut().enumerate() {
                let p = start + j;
                *v *= if p < r0 {
                    0.0
                } else if p < r0 + n {
                    up(p - r0, n)
                } else {
                    1.0
                };
            }
        }
        if i + 1 < self.count() {
            let (r0, n) = self.ramps[i];
            for (j, v) in w.iter_mut().enumerate() {
                let p = start + j;
                *v *= if p < r0 {
                    1.0
                } else if p < r0 + n {
                    1.0 - up(p - r0, n)
                } else {
                    0.0
                };
            }
        }
        w
    }
}

/// Raised-cosine ramp value at step `j` of `n`, strictly inside (0, 1), so
/// that up and down ramps at the same samples sum to one.
fn up(j: usize, n: usize) -> f32 {
    (0.5 - 0.5 * (std::f64::consts::PI * (j as f64 + 0.5) / n as f64).cos()) as f32
}

/// One tile: where it sits in the packed image (its blend weights come from
/// the plan).
#[derive(Clone, Debug)]
pub struct Tile {
    /// Position in [`TilePlan::tiles`]'s order (row-major over the tiles).
    pub(crate) index: usize,
    /// Top row in the packed image.
    pub y: usize,
    /// Left column in the packed image.
    pub x: usize,
    /// Height in packed pixels.
    pub h: usize,
    /// Width in packed pixels.
    pub w: usize,
}

/// The tiles covering a packed `(C, H, W)` image: every combination of a
/// row tile and a column tile.
#[derive(Clone, Debug)]
pub struct TilePlan {
    /// The tiles along the height.
    pub rows: AxisPlan,
    /// The tiles along the width.
    pub cols: AxisPlan,
}

impl TilePlan {
    /// Square tiles of side `tile` over an `h` x `w` image, overlapping by at
    /// least `overlap` ([`AxisPlan::new`] along each axis).
    #[cfg(test)]
    pub(crate) fn new(h: usize, w: usize, tile: usize, overlap: usize) -> Result<TilePlan> {
        Ok(TilePlan {
            rows: AxisPlan::new(h, tile, overlap)?,
            cols: AxisPlan::new(w, tile, overlap)?,
        })
    }

    /// Tiles in all.
    pub fn count(&self) -> usize {
        self.rows.count() * self.cols.count()
    }

    /// Every tile, row by row.
    pub fn tiles(&self) -> Vec<Tile> {
        let mut out = Vec::with_capacity(self.count());
        for &y in &self.rows.starts {
            for &x in &self.cols.starts {
                out.push(Tile {
                    index: out.len(),
                    y,
                    x,
                    h: self.rows.len,
                    w: self.cols.len,
                });
            }
        }
        out
    }

    /// The tile's 2-D weights: the product of its row and column weights.
    pub(crate) fn weights(&self, tile: &Tile) -> Array2<f32> {
        let nc = self.cols.count();
        let wy = self.rows.weights(tile.index / nc);
        let wx = self.cols.weights(tile.index % nc);
        Array2::from_shape_fn((tile.h, tile.w), |(i, j)| wy[i] * wx[j])
    }
}

/// Accumulates blended tile outputs into the full image.
pub(crate) struct Blender {
    plan: TilePlan,
    sum: Array3<f32>,
}

impl Blender {
    /// An empty `(channels, h, w)` image to blend the tiles of `plan` into.
    pub(crate) fn new(plan: TilePlan, channels: usize, h: usize, w: usize) -> Blender {
        Blender {
            plan,
            sum: Array3::zeros((channels, h, w)),
        }
    }

    /// Add `out`, the output for `tile`, times the tile's weights.
    pub(crate) fn add(&mut self, tile: &Tile, out: ArrayView3<f32>) -> Result<()> {
        let c = self.sum.shape()[0];
        if out.shape() != [c, tile.h, tile.w] {
            return Err(NnError::SizeMismatch(format!(
                "tile output has shape {:?}, expected [{c}, {}, {}]",
                out.shape(),
                tile.h,
                tile.w
            )));
        }
        let weights = self.plan.weights(tile);
        let mut dst = self
            .sum
            .slice_mut(s![.., tile.y..tile.y + tile.h, tile.x..tile.x + tile.w]);
        for (mut d, o) in dst.axis_iter_mut(Axis(0)).zip(out.axis_iter(Axis(0))) {
            ndarray::Zip::from(&mut d)
                .and(&o)
                .and(&weights)
                .for_each(|d, &o, &w| *d += w * o);
        }
        Ok(())
    }

    /// The blended image (the weights already sum to one everywhere).
    pub(crate) fn finish(self) -> Array3<f32> {
        self.sum
    }
}

/// Run `f` on every tile of `inputs` (all `(C, H, W)` of one size) and blend.
pub(crate) fn run_tiled(
    inputs: &[ArrayView3<f32>],
    out_channels: usize,
    plan: &TilePlan,
    mut f: impl FnMut(&Tile, &[ArrayView3<f32>]) -> Result<Array3<f32>>,
) -> Result<Array3<f32>> {
    let shape = inputs
        .first()
        .ok_or_else(|| NnError::Invalid("no input to tile".into()))?
        .shape()
        .to_vec();
    if inputs.iter().any(|a| a.shape() != shape.as_slice()) {
        return Err(NnError::SizeMismatch("tiled inputs differ in shape".into()));
    }
    let (h, w) = (shape[1], shape[2]);
    let mut blend = Blender::new(plan.clone(), out_channels, h, w);
    for tile in plan.tiles() {
        let views: Vec<ArrayView3<f32>> = inputs
            .iter()
            .map(|a| a.slice(s![.., tile.y..tile.y + tile.h, tile.x..tile.x + tile.w]))
            .collect();
        let out = f(&tile, &views)?;
        blend.add(&tile, out.view())?;
    }
    Ok(blend.finish())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_cover_the_axis_and_weights_sum_to_one() {
        // Overlaps from a quarter up to half the tile, and last tiles that
        // land just past their neighbour (131 = 64 + 64 + 3).
        for (total, tile, overlap) in [
            (1000, 256, 64),
            (257, 256, 64),
            (513, 128, 32),
            (90, 40, 8),
            (1000, 128, 64),
            (513, 64, 32),
            (131, 64, 32),
            (129, 64, 31),
        ] {
            let p = AxisPlan::new(total, tile, overlap).unwrap();
            assert_eq!(p.starts[0], 0);
            assert_eq!(p.starts.last().unwrap() + p.len, total);
            let mut sum = vec![0.0f64; total];
            let mut blended = vec![0usize; total];
            for i in 0..p.count() {
                for (j, w) in p.weights(i).iter().enumerate() {
                    assert!((0.0..=1.0).contains(w));
                    sum[p.starts[i] + j] += *w as f64;
                    blended[p.starts[i] + j] += (*w > 0.0) as usize;
                }
            }
            for (k, s) in sum.iter().enumerate() {
                assert!((s - 1.0).abs() < 1e-6, "{total}/{tile}: sum {s} at {k}");
                assert!(
                    blended[k] <= 2,
                    "{total}/{tile}: {} tiles at {k}",
                    blended[k]
                );
            }
        }
    }

    #[test]
    fn a_frame_that_fits_is_one_tile() {
        let p = TilePlan::new(100, 60, 128, 32).unwrap();
        assert_eq!(p.count(), 1);
        assert!(p.weights(&p.tiles()[0]).iter().all(|&w| w == 1.0));
    }

    #[test]
    fn bad_overlaps_are_refused() {
        assert!(AxisPlan::new(1000, 100, 51).is_err());
        assert!(AxisPlan::new(1000, 100, 50).is_ok());
        assert!(AxisPlan::new(1000, 100, 0).is_err());
        assert!(AxisPlan::new(0, 100, 10).is_err());
    }

    /// A local operator (3x3 box mean with edge clamping) of radius 1 needs
    /// a margin of 1: tiling with overlap 16 (margin 4) reproduces it exactly.
    #[test]
    fn tiling_a_local_operator_reproduces_it_exactly() {
        let (h, w) = (70, 53);
        let img = Array3::from_shape_fn((2, h, w), |(c, i, j)| {
            ((i * 31 + j * 17 + c * 7) % 23) as f32 / 23.0
        });
        let boxf = |a: ArrayView3<f32>| -> Array3<f32> {
            let (c, h, w) = a.dim();
            Array3::from_shape_fn((c, h, w), |(k, i, j)| {
                let mut s = 0.0;
                for di in -1i64..=1 {
                    for dj in -1i64..=1 {
                        let y = (i as i64 + di).clamp(0, h as i64 - 1) as usize;
                        let x = (j as i64 + dj).clamp(0, w as i64 - 1) as usize;
                        s += a[[k, y, x]];
                    }
                }
                s / 9.0
            })
        };
        let whole = boxf(img.view());
        let plan = TilePlan::new(h, w, 24, 6).unwrap();
        assert!(plan.count() > 6);
        let tiled = run_tiled(&[img.view()], 2, &plan, |_, v| Ok(boxf(v[0]))).unwrap();
        let worst = (&tiled - &whole).iter().fold(0.0f32, |m, d| m.max(d.abs()));
        assert!(worst < 1e-6, "worst {worst}");
    }
}
