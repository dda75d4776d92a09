//! Restoring a whole packed frame: the flow's start fields, the tiles, the
//! blend, and the final clamp.

use super::restorer::Restore;
use super::start::start_noise;
use super::tiles::{run_tiled, AxisPlan, TilePlan};
use crate::condition::NoiseLevel;
use crate::error::{NnError, Result};
use crate::norm::window_padding;
use ndarray::{s, Array3, ArrayView3};
use pgrf_core::Progress;

/// How a frame is cut into tiles and which start noise the flow draws.
#[derive(Clone, Copy, Debug)]
pub struct ImageOptions {
    /// Tile side in packed pixels (a frame that fits is one tile).
    pub tile: usize,
    /// Minimum overlap between neighbouring tiles, packed pixels.
    pub overlap: usize,
    /// Seed of the flow's X0 (sample k uses stream k).
    pub seed: u64,
    /// The input's noise level, for a conditioned network (pixelwise, so
    /// the same for every tile).
    pub noise: Option<NoiseLevel>,
}

/// Default overlap: 64 packed pixels; a quarter of it on each side is
/// discarded, the middle half is blended.
pub const DEFAULT_OVERLAP: usize = 64;

/// The smallest tile a user may ask for when the frame does not fit in one.
/// Measured on the demo photo's 1024 x 768 window at x100 with the shipped
/// SID U-Net and overlap 64 (docs/guide.md, "Tiling"): tiles of 128 differ from one
/// whole-frame pass by 49.5 dB PSNR, of 144 by 51.4, of 192 by 53.9; the
/// convolutional network's tiles converge as they grow, so 144 is where
/// the result stops depending on the tiling (> 50 dB). A flow network
/// restores within windows of its training crop, and its tiles are whole
/// windows, at least two when the frame does not fit in one
/// ([`frame_plan`]); below 144 its border losses grow too, so the bound
/// holds for both.
pub const MIN_TILE: usize = 144;

/// The smallest overlap a user may ask for when a frame is tiled: with less
/// the tiles' discarded borders (a quarter of the overlap) fall below 16
/// pixels and the SID U-Net's tiles of 128 differ from the whole frame by
/// 44.1 dB (overlap 32) and 46.2 dB (48) instead of 49.5 (64).
pub const MIN_OVERLAP: usize = DEFAULT_OVERLAP;

/// A tiling setting `flag` refused, `message` saying why.
fn bad(flag: &'static str, message: String) -> NnError {
    NnError::BadSetting { flag, message }
}

/// A tile or overlap the user gave, checked against [`MIN_TILE`] and
/// [`MIN_OVERLAP`] before any work (the commands call it with their
/// arguments, [`super::restore_packed`] again with its [`super::Tiling`]).
/// The bound holds whatever the frame's size: a frame that fits in a tile
/// of 100 fits in one of 144 too.
pub fn check_tiling_args(tile: Option<usize>, overlap: Option<usize>) -> Result<()> {
    if let Some(t) = tile.filter(|&t| t < MIN_TILE) {
        return Err(bad("--tile", format!(
            "--tile {t} is below {MIN_TILE}: smaller tiles make the result depend on the tiling (its PSNR against one whole-frame pass falls below 50 dB; docs/guide.md, \"Tiling\"); give --tile {MIN_TILE} or more, or leave it out"
        )));
    }
    if let Some(o) = overlap.filter(|&o| o < MIN_OVERLAP) {
        return Err(bad("--overlap", format!(
            "--overlap {o} is below {MIN_OVERLAP}: with less the tiles' borders show in the result (docs/guide.md, \"Tiling\"); give --overlap {MIN_OVERLAP} or more, or leave it out"
        )));
    }
    Ok(())
}

/// The overlap used when none is given: [`DEFAULT_OVERLAP`], or half of a
/// smaller tile (a tile must be at least 2x its overlap, so that no pixel
/// lies in more than two tiles' handover). Half, not less: what a tile
/// discards at an inner border is a quarter of the overlap, and below 16
/// discarded pixels the networks' border effects reach the blend (tiles of
/// 128 with overlap 32 differed from one whole-frame pass by 49 dB PSNR,
/// with overlap 64 by more than 50: docs/guide.md, "Tiling").
pub(crate) fn overlap_for(tile: usize) -> usize {
    DEFAULT_OVERLAP.min(tile / 2)
}

/// The restored frame in [0, 1], `(4, H, W)` like `input` (packed, amplified,
/// in [0, 1]): `r` run on the tiles of `opts` (see [`plan_for`]), each tile
/// given its window of the frame-wide start fields X0 (sample k drawn from
/// stream k of `opts.seed`), the tiles blended, the result clamped.
/// `progress` hears one `advance` per tile. Refuses a non-finite input and a
/// NaN output.
pub fn restore_image(
    r: &dyn Restore,
    input: ArrayView3<f32>,
    opts: &ImageOptions,
    progress: &dyn Progress,
) -> Result<Array3<f32>> {
    let (c, h, w) = input.dim();
    if let Some(pos) = input.iter().position(|v| !v.is_finite()) {
        return Err(NnError::NonFiniteInput { index: pos });
    }
    let (m, ph, pw) = frame_padding(h, w, r.window());
    let plan = frame_plan(r, h, w, opts)?;
    let pad = |a: ArrayView3<f32>| reflect_pad(a, m, ph, pw);
    let padded = pad(input);
    let x0s: Vec<Array3<f32>> = (0..r.samples() as u64)
        .map(|k| pad(start_noise(opts.seed, k, c, h, w).view()))
        .collect();
    let mut inputs = vec![padded.view()];
    inputs.extend(x0s.iter().map(|a| a.view()));
    let out = run_tiled(&inputs, c, &plan, |_, views| {
        let y = r.restore(views[0], &views[1..], opts.noise)?;
        progress.advance(1);
        Ok(y)
    })?;
    let mut out = out.slice(s![.., m..m + h, m..m + w]).to_owned();
    if let Some(pos) = out.iter().position(|v| v.is_nan()) {
        return Err(NnError::NanOutput { index: pos });
    }
    out.mapv_inplace(|v| v.clamp(0.0, 1.0));
    Ok(out)
}

/// The tiles `r` runs on an `h` x `w` packed frame: [`plan_for`], on the
/// frame padded to whole windows and with the overlap rounded up to whole
/// windows where `r` has them ([`Restore::window`]).
pub fn frame_plan(r: &dyn Restore, h: usize, w: usize, opts: &ImageOptions) -> Result<TilePlan> {
    let window = r.window();
    let (m, ph, pw) = frame_padding(h, w, window);
    let (h2, w2) = (h + 2 * m + ph, w + 2 * m + pw);
    let padded = h2.max(w2);
    let opts = ImageOptions {
        // A tile that holds the whole frame holds it padded too.
        tile: if opts.tile >= h.max(w) {
            opts.tile.max(padded)
        } else {
            opts.tile
        },
        // With windows the overlap is whole windows too (one at least), so
        // that every tile of the padded frame (multiples of the window, the
        // last flush with its end) starts on the window grid.
        overlap: match window {
            0 => opts.overlap,
            s => opts.overlap.div_ceil(s).max(1) * s,
        },
        ..*opts
    };
    plan_for(h2, w2, &opts, r.side_multiple())
}

/// How an `h` x `w` packed frame is padded before it is tiled: mirrored by
/// its edge margin `m` on every side ([`EDGE_MARGIN`]), then, for a flow
/// network with windows of side `window`, by `ph` more rows below and `pw`
/// more columns on the right to whole windows, so that its tiles
/// (multiples of the window, overlapping by multiples of it, the last
/// flush with the padded end) all sit on the padded frame's window grid.
/// Returns (m, ph, pw).
fn frame_padding(h: usize, w: usize, window: usize) -> (usize, usize, usize) {
    let m = edge_margin(h, w);
    let (ph, pw) = window_padding(h + 2 * m, w + 2 * m, window);
    (m, ph, pw)
}

/// Packed pixels of the frame mirrored on every side before it is
/// restored, and cut off after. Why: the networks' convolutions pad with
/// zeros, and at the frame's outermost packed row and column that left
/// the noise half removed (mean |error| 5.4x the interior's on a smooth
/// frame at A7S2 ISO 1600 x100, the second row 1.8x: a noisy line around
/// every picture). One mirrored pixel moves the zeros away from the
/// picture; 1, 2, 4 and 8 gave the same to 0.01 dB on issue 36's measure
/// (+0.2 to +0.7 dB there, on 256 x 256 crops), 4 the best by that much
/// (MODELS.md, "The frame's edge").
pub const EDGE_MARGIN: usize = 4;

/// [`EDGE_MARGIN`], or less for a frame too small to mirror it (a side of
/// n mirrors at most n - 1 pixels).
fn edge_margin(h: usize, w: usize) -> usize {
    EDGE_MARGIN.min(h.min(w).saturating_sub(1))
}

/// `a` `(c, h, w)` mirrored by `m` pixels on every side, then extended by
/// `ph` rows below and `pw` columns on the right mirrored about the
/// extended frame's last row and column (the edge never repeated, as the
/// network's own reflection padding does; a mirror folds back for pads
/// longer than what it mirrors): one copy. What [`restore_image`]
/// restores (with [`EDGE_MARGIN`] and its windows' padding) before it cuts
/// the padding off again.
pub fn reflect_pad(a: ArrayView3<f32>, m: usize, ph: usize, pw: usize) -> Array3<f32> {
    let (c, h, w) = a.dim();
    // Index i of a run of n (negative: before it), mirrored into 0..n.
    let fold = |i: isize, n: usize| -> usize {
        if n == 1 {
            return 0;
        }
        let p = 2 * (n - 1);
        let k = i.rem_euclid(p as isize) as usize;
        if k < n {
            k
        } else {
            p - k
        }
    };
    // Into the frame mirrored by m, then into the frame itself.
    let at = |i: usize, n: usize| fold(fold(i as isize, n + 2 * m) as isize - m as isize, n);
    Array3::from_shape_fn((c, h + 2 * m + ph, w + 2 * m + pw), |(k, i, j)| {
        a[[k, at(i, h), at(j, w)]]
    })
}

/// The tile side actually run for a requested `tile` on a frame whose
/// longer side is `longest`: the request when the whole frame fits, else
/// rounded down to the network's side multiple `m` (at least `m`).
pub(crate) fn round_tile(tile: usize, longest: usize, m: usize) -> usize {
    if tile >= longest {
        tile
    } else {
        (tile / m * m).max(m)
    }
}

/// Tiles of `opts.tile` rounded down to the network's side multiple (so no
/// tile is padded inside the network), unless the whole frame fits. Along
/// each axis the tiles are then shrunk to the smallest multiple that still
/// covers it with as many tiles: 2128 columns in tiles of 2048 become two
/// tiles of 1104, not a second tile of 2048 that repeats 1968 columns.
/// `h` x `w` is the packed frame's size, `multiple` the network's side
/// multiple ([`crate::Restore::side_multiple`]).
pub fn plan_for(h: usize, w: usize, opts: &ImageOptions, multiple: usize) -> Result<TilePlan> {
    let m = multiple.max(1);
    let o = opts.overlap;
    if opts.tile < m.max(4) && opts.tile < h.max(w) {
        return Err(bad("--tile", format!(
            "tile {} is too small: tiles are at least {} packed pixels (and a multiple of the network's {m})",
            opts.tile,
            m.max(4)
        )));
    }
    let tile = round_tile(opts.tile, h.max(w), m);
    if tile < 2 * o && tile < h.max(w) {
        let rounded = if tile == opts.tile {
            String::new()
        } else {
            format!(" (rounded down to {tile}, a multiple of the network's {m})")
        };
        return Err(bad("--tile", format!(
            "tile {}{rounded} is too small for overlap {o}: a tile must be at least 2x its overlap; give a tile of at least {} or a smaller overlap",
            opts.tile,
            (2 * o).div_ceil(m) * m
        )));
    }
    let balanced = |len: usize| -> usize {
        if tile >= len {
            return tile;
        }
        let n = (len - o).div_ceil(tile - o);
        let even = (len + (n - 1) * o).div_ceil(n).div_ceil(m) * m;
        if even >= 2 * o && even <= tile {
            even
        } else {
            tile
        }
    };
    Ok(TilePlan {
        rows: AxisPlan::new(h, balanced(h), o)?,
        cols: AxisPlan::new(w, balanced(w), o)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The margin mirrors about the outermost pixels without repeating
    /// them, on every side, and the frame itself stays in place.
    #[test]
    fn the_edge_margin_mirrors_every_side() {
        let a = Array3::from_shape_fn((1, 3, 5), |(_, y, x)| (10 * y + x) as f32);
        let p = reflect_pad(a.view(), 2, 0, 0);
        assert_eq!(p.dim(), (1, 7, 9));
        assert_eq!(p.slice(s![.., 2..5, 2..7]), a);
        let row = |i: usize| p.slice(s![0, i, ..]).to_vec();
        assert_eq!(row(2), [2., 1., 0., 1., 2., 3., 4., 3., 2.]);
        assert_eq!(row(0), [22., 21., 20., 21., 22., 23., 24., 23., 22.]);
        assert_eq!(row(6), [2., 1., 0., 1., 2., 3., 4., 3., 2.]);
        // The windows' padding mirrors the margin-extended frame and folds
        // back when longer: [0 1 2] by 1 is [1 0 1 2 1], then 6 more.
        let r = Array3::from_shape_fn((1, 1, 3), |(_, _, x)| x as f32);
        let p = reflect_pad(r.view(), 1, 0, 6);
        assert_eq!(
            p.slice(s![0, 1, ..]).to_vec(),
            [1., 0., 1., 2., 1., 2., 1., 0., 1., 0., 1.]
        );
        assert_eq!(
            (
                edge_margin(3, 5),
                edge_margin(1000, 1000),
                edge_margin(1, 9)
            ),
            (2, EDGE_MARGIN, 0)
        );
    }

    #[test]
    fn tiles_are_multiples_of_the_network_side() {
        let o = ImageOptions {
            tile: 300,
            overlap: 64,
            seed: 0,
            noise: None,
        };
        // 300 -> 288; 1424 rows need 7 tiles of 288 (stride 224), which
        // tiles of 272 also cover; 2128 columns need 10, also of 272.
        let p = plan_for(1424, 2128, &o, 16).unwrap();
        assert_eq!((p.rows.len, p.rows.count()), (272, 7));
        assert_eq!((p.cols.len, p.cols.count()), (272, 10));
        let wide = ImageOptions { tile: 2048, ..o };
        let p = plan_for(1424, 2128, &wide, 16).unwrap();
        assert_eq!((p.cols.len, p.cols.count()), (1104, 2));
        let p = plan_for(200, 250, &o, 16).unwrap();
        assert_eq!(p.count(), 1);
        let small = ImageOptions { tile: 112, ..o };
        assert!(plan_for(1000, 1000, &small, 16).is_err());
        // The default overlap for a small tile is half of it, which plans:
        // 1000 / (112 - 56) -> 17 tiles a side.
        assert_eq!(
            (overlap_for(1024), overlap_for(128), overlap_for(112)),
            (64, 64, 56)
        );
        let fitted = ImageOptions {
            overlap: overlap_for(112),
            ..small
        };
        let p = plan_for(1000, 1000, &fitted, 8).unwrap();
        assert_eq!((p.rows.count(), p.cols.count()), (17, 17));
    }

    /// Every tile a user may ask for plans with the default overlap of the
    /// tile as it runs (issue 17: 100 = 4 x 25 was refused), and the ones
    /// that cannot run say why with the numbers that would.
    #[test]
    fn every_reasonable_tile_plans_and_the_rest_say_what_would() {
        for tile in [16, 31, 63, 64, 72, 100, 101, 104, 120, 127, 128, 300] {
            let o = overlap_for(round_tile(tile, 1000, 16));
            let opts = ImageOptions {
                tile,
                overlap: o,
                seed: 0,
                noise: None,
            };
            let p = plan_for(1000, 800, &opts, 16);
            assert!(p.is_ok(), "tile {tile}, overlap {o}: {:?}", p.err());
        }
        for tile in [0, 3, 15] {
            let opts = ImageOptions {
                tile,
                overlap: overlap_for(round_tile(tile, 1000, 16)),
                seed: 0,
                noise: None,
            };
            let e = plan_for(1000, 800, &opts, 16).unwrap_err().to_string();
            assert!(
                e.contains("too small: tiles are at least 16"),
                "{tile}: {e}"
            );
        }
        // An explicit overlap too large for the tile names the tile needed.
        let opts = ImageOptions {
            tile: 100,
            overlap: 56,
            seed: 0,
            noise: None,
        };
        let e = plan_for(1000, 800, &opts, 16).unwrap_err().to_string();
        assert!(
            e.contains("rounded down to 96") && e.contains("at least 112"),
            "{e}"
        );
    }

    /// A user's tile below 144 or overlap below 64 is refused whatever the
    /// frame; the library's own small tiles (tests, benches) go through
    /// `plan_for` unchecked.
    #[test]
    fn user_tiles_below_the_bound_are_refused() {
        assert!(check_tiling_args(Some(144), Some(64)).is_ok());
        assert!(check_tiling_args(None, None).is_ok());
        assert!(check_tiling_args(Some(4096), Some(500)).is_ok());
        let e = check_tiling_args(Some(143), None).unwrap_err().to_string();
        assert!(e.contains("--tile 143 is below 144"), "{e}");
        let e = check_tiling_args(None, Some(63)).unwrap_err().to_string();
        assert!(e.contains("--overlap 63 is below 64"), "{e}");
        let e = check_tiling_args(Some(0), Some(0)).unwrap_err().to_string();
        assert!(e.contains("--tile 0"), "{e}");
    }
}
