//! The dead-leaves painting process.
//!
//! Why dead leaves: occluding discs whose radii follow a density ~ r^-3 give
//! an image with the scale-invariant statistics of natural photographs (a
//! power-law spectrum, edges at every scale, regions of every size, each
//! octave of sizes taking about the same share of the area), which is what a
//! denoiser must learn to keep apart from noise. Real photos would do too,
//! but cannot be generated on the fly, carry their own noise and are not
//! reproducible from a seed.
//!
//! Discs are painted front to back: a pixel once covered is never
//! overwritten, so the first disc is on top and painting stops when nothing
//! is left uncovered. Covering the last pixels by chance takes most of the
//! draws (the uncovered share only falls as e^-n with n covers of the image),
//! so once a small share is left, each remaining gap gets the disc that
//! would cover it first in the random sequence, drawn directly: radius from
//! the size-biased law (density ~ r^-1, since a disc covers a given point
//! with probability ~ r^2) and centre uniform within that radius of the
//! point. That is exactly the law of the leaf seen at a point. Such a leaf
//! paints only near its gap (see `GAP_REACH`), so what is approximated is
//! which leaf wins neighbouring gaps, for a fraction of a percent of the
//! pixels.

use super::cover::Coverage;
use super::leaf::{lattice_table, Disc, Palette};
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

/// Smallest disc radius in mosaic pixels: a disc this small still covers the
/// 3x3 block around its centre, so the finest regions are about one packed
/// pixel wide (detail at the Nyquist limit of each colour plane).
const R_MIN: f64 = 1.5;
/// Largest radius as a fraction of the longer image side: one disc may cover
/// much of a crop, as a wall or sky does in a photograph.
const R_MAX_FRACTION: f64 = 0.5;
/// Uncovered share at which painting by chance gives way to filling gaps.
/// About 5 covers of the image get there, against about 14 (ln of the pixel
/// count) to finish a 1-megapixel scene by chance.
const TAIL_FRACTION: f64 = 0.005;
/// How far (in pixels, each way) a gap's disc may paint. Unclipped, the
/// size-biased law makes a third of these discs larger than 64 pixels, and
/// each would claim every gap under it, so a few dozen large discs would own
/// all the gaps; in the real sequence many small discs fill them first. The
/// clip keeps a gap's leaf local, so each gap cluster gets its own leaf.
const GAP_REACH: usize = 4;
/// A bound on chance draws whatever happens (tiny images have no tail):
/// e^-24 of the area would be left to gap filling on average.
const COVER_UNITS: f64 = 24.0;

/// What the painting pass leaves besides the pixels it visited.
pub(super) struct Painted {
    /// Visible regions in id order.
    pub(super) discs: Vec<Disc>,
    /// The value-noise lattice the discs' textures read.
    pub(super) table: Vec<f32>,
    /// Discs drawn, hidden ones included.
    pub(super) drawn: usize,
}

/// Paint a `width` x `height` dead-leaves scene front to back. For every
/// visible disc, `visit(region, disc, table, pixels)` receives the (row, col)
/// of the pixels it owns; every pixel is visited exactly once. Handing the
/// pixels over as they are painted lets a caller write samples straight into
/// its output (the data loader's path) while the disc is in cache, with no
/// id map to store and read back.
pub(super) fn paint(
    width: usize,
    height: usize,
    seed: u64,
    mut visit: impl FnMut(u32, &Disc, &[f32], &[[u32; 2]]),
) -> Painted {
    // Geometry and appearance draw from separate streams, and appearance
    // only for discs that turn out visible, so hidden discs cost three
    // numbers each.
    let mut geo = Xoshiro256PlusPlus::seed_from_u64(pgrf_core::seed::mix64(seed ^ 0x6765_6f6d));
    let mut app = Xoshiro256PlusPlus::seed_from_u64(pgrf_core::seed::mix64(seed ^ 0x636f_6c72));
    let palette = Palette::new(&mut app, width, height);
    let table = lattice_table(&mut app);
    let mut discs = Vec::new();
    let mut drawn = 0;
    if width == 0 || height == 0 {
        return Painted {
            discs,
            table,
            drawn,
        };
    }

    let r_max = (R_MAX_FRACTION * width.max(height) as f64).max(R_MIN);
    let (a, b) = (1.0 / (R_MIN * R_MIN), 1.0 / (r_max * r_max));
    // E[r^2] under density ~ r^-3 on [R_MIN, r_max].
    let mean_r2 = if r_max > R_MIN {
        (r_max / R_MIN).ln() / (0.5 * (a - b))
    } else {
        R_MIN * R_MIN
    };
    let area = (width * height) as f64;
    let cap = (COVER_UNITS * area / (std::f64::consts::PI * mean_r2)).ceil() as usize;
    let tail = (TAIL_FRACTION * area) as usize;

    let mut cover = Coverage::new(width, height);
    let mut pixels = Vec::new();
    let all = [0, height - 1, 0, width - 1];
    let mut emit = |r: f64,
                    cx: f64,
                    cy: f64,
                    clip: [usize; 4],
                    cover: &mut Coverage,
                    discs: &mut Vec<Disc>| {
        pixels.clear();
        if cover.paint(cx, cy, r, clip, &mut pixels) > 0 {
            let d = palette.disc(&mut app, r, cx, cy);
            visit(discs.len() as u32, &d, &table, &pixels);
            discs.push(d);
        }
    };

    let (wmax, hmax) = ((width - 1) as f64, (height - 1) as f64);
    while cover.remaining() > tail && drawn < cap {
        drawn += 1;
        // Inverse CDF of r^-3.
        let u: f64 = geo.random();
        let r = 1.0 / (a - u * (a - b)).sqrt();
        // Centres range over the image grown by r, so pixels near the
        // border are as likely to be covered as those in the middle.
        let cx = -r + geo.random::<f64>() * (wmax + 2.0 * r);
        let cy = -r + geo.random::<f64>() * (hmax + 2.0 * r);
        emit(r, cx, cy, all, &mut cover, &mut discs);
    }

    // Gaps in random order, so no direction of the image is favoured when
    // two gaps compete for one disc.
    let mut gaps = cover.uncovered();
    for i in (1..gaps.len()).rev() {
        gaps.swap(i, geo.random_range(0..=i));
    }
    let log_ratio = (r_max / R_MIN).ln();
    for [row, col] in gaps {
        let (row_us, col_us) = (row as usize, col as usize);
        let window = [
            row_us.saturating_sub(GAP_REACH),
            (row_us + GAP_REACH).min(height - 1),
            col_us.saturating_sub(GAP_REACH),
            (col_us + GAP_REACH).min(width - 1),
        ];
        // Loops only if rounding put the point just outside its own disc.
        while !cover.is_covered(row, col) {
            drawn += 1;
            let r = R_MIN * (geo.random::<f64>() * log_ratio).exp();
            let (ox, oy) = loop {
                let (x, y) = (
                    geo.random::<f64>() * 2.0 - 1.0,
                    geo.random::<f64>() * 2.0 - 1.0,
                );
                if x * x + y * y <= 1.0 {
                    break (x, y);
                }
            };
            let (cx, cy) = (col as f64 + ox * r, row as f64 + oy * r);
            emit(r, cx, cy, window, &mut cover, &mut discs);
        }
    }
    debug_assert_eq!(cover.remaining(), 0);
    Painted {
        discs,
        table,
        drawn,
    }
}

/// A dead-leaves layout kept as a region id per mosaic pixel, for callers
/// that sample one scene several ways (full RGB, every CFA phase) or ask
/// which region a pixel belongs to.
pub(super) struct DeadLeaves {
    width: usize,
    ids: Vec<u32>,
    pub(super) painted: Painted,
}

impl DeadLeaves {
    pub(super) fn new(width: usize, height: usize, seed: u64) -> Self {
        let mut ids = vec![u32::MAX; width * height];
        let painted = paint(width, height, seed, |id, _, _, pixels| {
            for &[row, col] in pixels {
                ids[row as usize * width + col as usize] = id;
            }
        });
        DeadLeaves {
            width,
            ids,
            painted,
        }
    }

    /// Region id of the mosaic pixel at (row, col).
    #[inline]
    pub(super) fn region_at(&self, row: usize, col: usize) -> u32 {
        self.ids[row * self.width + col]
    }

    /// Channel `c` at (row, col), in [0, 1].
    #[inline]
    pub(super) fn sample(&self, row: usize, col: usize, c: usize) -> f32 {
        let d = &self.painted.discs[self.region_at(row, col) as usize];
        d.value(c, d.shade(&self.painted.table, row as u32, col as u32))
    }

    /// All three channels at (row, col).
    #[inline]
    pub(super) fn sample_rgb(&self, row: usize, col: usize) -> [f32; 3] {
        let d = &self.painted.discs[self.region_at(row, col) as usize];
        let s = d.shade(&self.painted.table, row as u32, col as u32);
        [d.value(0, s), d.value(1, s), d.value(2, s)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_pixel_gets_a_region_and_the_first_disc_is_on_top() {
        for (w, h, seed) in [(300, 200, 5), (37, 5, 1), (1, 1, 2), (64, 64, 3)] {
            let s = DeadLeaves::new(w, h, seed);
            assert!(s.ids.iter().all(|&id| id != u32::MAX), "{w}x{h}");
            assert!(s.painted.drawn >= s.painted.discs.len());
            // Nothing was visible before region 0 was drawn, so it owns every
            // pixel inside it, however many discs came after.
            let d = &s.painted.discs[0];
            for row in 0..h {
                for col in 0..w {
                    let (dx, dy) = (col as f32 - d.cx, row as f32 - d.cy);
                    if dx * dx + dy * dy < d.r * d.r - 0.01 {
                        assert_eq!(s.region_at(row, col), 0, "({row}, {col})");
                    }
                }
            }
        }
    }

    #[test]
    fn each_octave_of_sizes_takes_a_similar_share_of_the_area() {
        // The scale invariance dead leaves are chosen for: the leaf seen at a
        // point has radius density ~ 1/r, the same area per octave.
        let mut share = [0usize; 5];
        let mut total = 0;
        for seed in 0..4 {
            let s = DeadLeaves::new(512, 512, 40 + seed);
            for &id in &s.ids {
                let r = s.painted.discs[id as usize].r as f64;
                let octave = (r / R_MIN).log2().floor() as usize;
                if octave < share.len() {
                    share[octave] += 1;
                }
                total += 1;
            }
        }
        // ln 2 / ln(256 / 1.5) = 13.5% per octave in theory.
        let share = share.map(|n| n as f64 / total as f64);
        for (k, f) in share.iter().enumerate() {
            assert!((0.08..0.2).contains(f), "octave {k}: {share:?}");
        }
    }
}
