//! The demo's picture: dead leaves (texture, sharp edges, natural size
//! statistics) with a ColorChecker in the upper right and a neutral ramp
//! along the bottom. One frame shows the three things a denoiser can ruin:
//! fine detail, colour, and smooth tones.

use crate::chart::patch_camera_rgb;
use crate::error::{Result, SceneError};
use crate::scene::{
    a7s2_neutral, frame_from_values, plane_lut, Scene, SceneKind, SceneLevels, SceneSpec, CHANNEL,
};
use pgrf_raw::{Cfa, RawFrame};

/// Light of a perfect white reflector on the chart (strongest channel): the
/// white patch lands near 0.7, bright but far from clipping.
pub const DEMO_CHART_EXPOSURE: f32 = 0.8;
/// The ramp runs linearly in light from 0 to this, short of clipping.
pub const DEMO_RAMP_TOP: f32 = 0.95;
/// The chart's surround, a dark grey card.
const SURROUND: f32 = 0.03;

/// Where things are, in mosaic pixels (all even, so the CFA phase is the
/// same at every corner).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DemoLayout {
    /// Chart card: rows and columns `[start, end)`.
    pub(crate) chart_rows: (usize, usize),
    pub(crate) chart_cols: (usize, usize),
    /// Ramp strip: rows `[start, end)`.
    pub ramp_rows: (usize, usize),
    /// Ramp strip: columns `[start, end)`; light rises linearly from 0 at
    /// the first column to [`DEMO_RAMP_TOP`] at the last.
    pub ramp_cols: (usize, usize),
}

fn even(v: usize) -> usize {
    v & !1
}

impl DemoLayout {
    /// The layout of a `width` x `height` demo frame: the chart card in the
    /// upper right, the ramp strip along the bottom; all bounds even.
    pub fn new(width: usize, height: usize) -> DemoLayout {
        let at = |n: usize, f: f32| even((n as f32 * f) as usize);
        DemoLayout {
            chart_rows: (at(height, 0.05), at(height, 0.55)),
            chart_cols: (at(width, 0.60), at(width, 0.96)),
            ramp_rows: (at(height, 0.84), at(height, 0.95)),
            ramp_cols: (at(width, 0.04), at(width, 0.96)),
        }
    }

    /// Patch `i`'s box `[r0, r1) x [c0, c1)`: a 6 x 4 grid in the card with
    /// a surround margin of a sixth of a cell.
    pub fn patch_box(&self, i: usize) -> (usize, usize, usize, usize) {
        let (r0, r1) = self.chart_rows;
        let (c0, c1) = self.chart_cols;
        let (ch, cw) = ((r1 - r0) / 4, (c1 - c0) / 6);
        let (pr, pc) = (i / 6, i % 6);
        let (mr, mc) = (ch / 6, cw / 6);
        (
            r0 + pr * ch + mr,
            r0 + (pr + 1) * ch - mr,
            c0 + pc * cw + mc,
            c0 + (pc + 1) * cw - mc,
        )
    }
}

/// Light of colour channel `ch` at mosaic pixel (row, col).
fn demo_sample(
    scene: &Scene,
    layout: &DemoLayout,
    neutral: &[f32; 3],
    row: usize,
    col: usize,
    ch: usize,
) -> f32 {
    let inside = |(a, b): (usize, usize), v: usize| v >= a && v < b;
    if inside(layout.chart_rows, row) && inside(layout.chart_cols, col) {
        for i in 0..24 {
            let (r0, r1, c0, c1) = layout.patch_box(i);
            if row >= r0 && row < r1 && col >= c0 && col < c1 {
                return DEMO_CHART_EXPOSURE * patch_camera_rgb(i)[ch];
            }
        }
        return SURROUND * neutral[ch];
    }
    if inside(layout.ramp_rows, row) && inside(layout.ramp_cols, col) {
        let (c0, c1) = layout.ramp_cols;
        let t = (col - c0) as f32 / (c1 - c0 - 1).max(1) as f32;
        return DEMO_RAMP_TOP * t * neutral[ch];
    }
    scene.sample(row, col, ch)
}

/// The demo frame, `width` x `height` mosaic pixels (even, at least 64 x 64)
/// through `cfa` with `levels`, from `seed`. Carries the A7S2 colour matrix
/// and the white balance of a neutral, like every procedural scene.
pub fn render_demo(
    width: usize,
    height: usize,
    seed: u64,
    cfa: Cfa,
    levels: &SceneLevels,
) -> Result<RawFrame> {
    if width < 64 || height < 64 || !width.is_multiple_of(2) || !height.is_multiple_of(2) {
        return Err(SceneError::DemoSize { width, height });
    }
    let spec = SceneSpec::new(SceneKind::DeadLeaves, width, height, seed);
    let scene = Scene::new(&spec);
    let layout = DemoLayout::new(width, height);
    let neutral = a7s2_neutral();
    let planes = plane_lut(cfa);
    let mut values = Vec::with_capacity(width * height);
    for row in 0..height {
        values.extend((0..width).map(|col| {
            let ch = CHANNEL[planes[row & 1][col & 1]];
            demo_sample(&scene, &layout, &neutral, row, col, ch)
        }));
    }
    let mut f = frame_from_values(&spec, cfa, levels, &values)?;
    f.model = "procedural demo: dead leaves, ColorChecker, ramp (A7S2 colour)".into();
    Ok(f)
}
