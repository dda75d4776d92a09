//! Procedural clean RAW scenes: dead leaves and a gradient, in linear camera
//! RGB, rendered from a seed.
//!
//! They exist so networks can be trained, and the pipeline tested, on an
//! unlimited supply of noise-free images that are reproducible from a u64
//! and cost nothing to store. A scene is a function of mosaic position:
//! [`render_rgb`] samples all three channels at every pixel, the packed and
//! frame renderers sample only the channel the CFA puts at each pixel, and
//! the two agree bit for bit (the frame only adds rounding to DN).
//!
//! Dead leaves can be rendered two ways. [`Scene`] keeps a region id per
//! pixel, for callers that look at one scene several ways or ask which
//! region a pixel is in. The free functions [`render_packed_cfa`] and
//! [`render_frame`] instead compute each pixel's sample the moment its disc
//! covers it, which is what keeps the data loader's render of a 512x512
//! packed crop at a few tens of milliseconds on one core.
//!
//! Everything is rendered on the calling thread: the packed renderer runs in
//! data-loader threads that are already parallel, and a serial renderer
//! cannot depend on the thread count. A seed gives the same bytes on every
//! run; only the few libm calls that draw a disc's colour (exp, powf, sin,
//! cos) could differ in the last bit between platforms.

mod cover;
mod deadleaves;
mod leaf;

use crate::chart::A7S2_D65_MATRIX;
use crate::error::{Result, SceneError};
use deadleaves::DeadLeaves;
use ndarray::Array3;
use pgrf_core::parse::ParseError;
use pgrf_raw::color::SRGB_TO_XYZ;
use pgrf_raw::{bits_for, Cfa, ColorMatrix, RawFrame};
use std::fmt;
use std::str::FromStr;

/// Which procedural scene to render.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SceneKind {
    /// Occluding discs with natural-image statistics: the training scene.
    DeadLeaves,
    /// Smooth ramps: a scene whose every value tests can predict.
    Gradient,
}

impl SceneKind {
    /// Every scene kind.
    pub const ALL: [SceneKind; 2] = [SceneKind::DeadLeaves, SceneKind::Gradient];

    /// The name the CLI and frame metadata use ("dead-leaves", "gradient");
    /// [`FromStr`] parses it back.
    pub fn name(self) -> &'static str {
        match self {
            SceneKind::DeadLeaves => "dead-leaves",
            SceneKind::Gradient => "gradient",
        }
    }
}

impl fmt::Display for SceneKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for SceneKind {
    type Err = ParseError;
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s.to_ascii_lowercase().replace('_', "-").as_str() {
            "dead-leaves" | "deadleaves" => Ok(SceneKind::DeadLeaves),
            "gradient" => Ok(SceneKind::Gradient),
            other => Err(ParseError::unknown_name(
                s,
                format!("scene '{other}' is not known (expected dead-leaves or gradient)"),
            )),
        }
    }
}

/// What to render. Sizes are in mosaic pixels, so a packed render is
/// `(height / 2, width / 2)` like packing a frame of that size.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SceneSpec {
    pub(crate) kind: SceneKind,
    pub(crate) width: usize,
    pub(crate) height: usize,
    /// The gradient ignores it: it is a fixed target whose values are known.
    pub(crate) seed: u64,
}

impl SceneSpec {
    /// A `kind` scene of `width` x `height` mosaic pixels drawn from `seed`
    /// (the same seed gives the same scene on any machine and thread count).
    pub fn new(kind: SceneKind, width: usize, height: usize, seed: u64) -> Self {
        SceneSpec {
            kind,
            width,
            height,
            seed,
        }
    }
}

/// Levels of a rendered frame. The default is a Sony A7S2 (the camera of the
/// ELD benchmark), so a rendered frame normalises like the test set does.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneLevels {
    /// Black level of the planes R, G1, B, G2 in DN.
    pub black: [f32; 4],
    /// Saturation level in DN; scene value 1.0 maps to it.
    pub white: u32,
    /// Bits per sample the frame declares; at least what `white` needs.
    pub bits: u32,
}

impl Default for SceneLevels {
    fn default() -> Self {
        SceneLevels {
            black: [512.0; 4],
            white: 16383,
            bits: 14,
        }
    }
}

/// Camera RGB of a neutral D65 surface through the A7S2 matrix, strongest
/// channel 1. Scenes are coloured relative to it so their channel balance is
/// that of a real raw file, not of sRGB.
pub(crate) fn a7s2_neutral() -> [f32; 3] {
    let xyz: [f64; 3] = std::array::from_fn(|i| SRGB_TO_XYZ[i].iter().sum());
    let cam: [f64; 3] =
        std::array::from_fn(|i| (0..3).map(|k| A7S2_D65_MATRIX[i][k] as f64 * xyz[k]).sum());
    let max = cam.iter().cloned().fold(f64::MIN, f64::max);
    cam.map(|v| (v / max) as f32)
}

/// A scene laid out once and sampled as often as needed: the geometry pass of
/// dead leaves is the expensive part, so tests and callers that want both
/// RGB and packed views of one scene build it once.
pub struct Scene {
    spec: SceneSpec,
    inner: Inner,
}

enum Inner {
    DeadLeaves(DeadLeaves),
    Gradient { sx: f32, sy: f32, sd: f32 },
}

impl Scene {
    /// Lay out the scene `spec` describes (for dead leaves: place every disc).
    pub fn new(spec: &SceneSpec) -> Self {
        let inner = match spec.kind {
            SceneKind::DeadLeaves => {
                Inner::DeadLeaves(DeadLeaves::new(spec.width, spec.height, spec.seed))
            }
            SceneKind::Gradient => {
                // Ramp lengths as divisors (n / n is exactly 1 in floating
                // point, n * (1 / n) is not), so the last row or column is
                // exactly 1.0, i.e. clipped, and the first exactly 0.
                let len = |n: usize| n.saturating_sub(1).max(1) as f32;
                Inner::Gradient {
                    sx: len(spec.width),
                    sy: len(spec.height),
                    sd: len((spec.width + spec.height).saturating_sub(1)),
                }
            }
        };
        Scene { spec: *spec, inner }
    }

    /// Visible discs for dead leaves; 1 for the gradient, which is a single
    /// smooth region.
    pub fn regions(&self) -> usize {
        match &self.inner {
            Inner::DeadLeaves(d) => d.painted.discs.len(),
            Inner::Gradient { .. } => 1,
        }
    }

    /// Region id of the mosaic pixel at (row, col): regions are numbered in
    /// painting order, so region 0 is the disc on top.
    pub fn region_at(&self, row: usize, col: usize) -> u32 {
        match &self.inner {
            Inner::DeadLeaves(d) => d.region_at(row, col),
            Inner::Gradient { .. } => 0,
        }
    }

    /// Discs the geometry pass drew, hidden ones included (0 for the gradient).
    pub fn discs_drawn(&self) -> usize {
        match &self.inner {
            Inner::DeadLeaves(d) => d.painted.drawn,
            Inner::Gradient { .. } => 0,
        }
    }

    /// Channel `c` (0 R, 1 G, 2 B) at mosaic pixel (row, col), in [0, 1].
    #[inline]
    pub(crate) fn sample(&self, row: usize, col: usize, c: usize) -> f32 {
        match &self.inner {
            Inner::DeadLeaves(d) => d.sample(row, col, c),
            &Inner::Gradient { sx, sy, sd } => gradient(sx, sy, sd, row, col)[c],
        }
    }

    /// `(height, width, 3)` linear camera RGB.
    pub fn rgb(&self) -> Array3<f32> {
        let (h, w) = (self.spec.height, self.spec.width);
        let mut data = Vec::with_capacity(h * w * 3);
        match &self.inner {
            Inner::DeadLeaves(d) => {
                for row in 0..h {
                    for col in 0..w {
                        data.extend_from_slice(&d.sample_rgb(row, col));
                    }
                }
            }
            &Inner::Gradient { sx, sy, sd } => {
                for row in 0..h {
                    for col in 0..w {
                        data.extend_from_slice(&gradient(sx, sy, sd, row, col));
                    }
                }
            }
        }
        Array3::from_shape_vec((h, w, 3), data).expect("h * w * 3 samples")
    }

    /// `(4, height / 2, width / 2)` planes R, G1, B, G2 for a sensor of phase
    /// `cfa`: each plane sampled at the mosaic positions it occupies.
    pub fn packed(&self, cfa: Cfa) -> Array3<f32> {
        match &self.inner {
            Inner::DeadLeaves(d) => self.packed_with(cfa, |r, c, ch| d.sample(r, c, ch)),
            &Inner::Gradient { sx, sy, sd } => {
                self.packed_with(cfa, |r, c, ch| gradient(sx, sy, sd, r, c)[ch])
            }
        }
    }

    /// One loop per plane, monomorphised per scene kind so the per-sample
    /// work inlines.
    fn packed_with(&self, cfa: Cfa, f: impl Fn(usize, usize, usize) -> f32) -> Array3<f32> {
        let (ph, pw) = (self.spec.height / 2, self.spec.width / 2);
        let mut data = Vec::with_capacity(4 * ph * pw);
        for (plane, &(dr, dc)) in cfa.offsets().iter().enumerate() {
            let ch = CHANNEL[plane];
            for i in 0..ph {
                let row = 2 * i + dr;
                data.extend((0..pw).map(|j| f(row, 2 * j + dc, ch)));
            }
        }
        Array3::from_shape_vec((4, ph, pw), data).expect("4 * ph * pw samples")
    }

    /// The scene as a RawFrame through `cfa` with `levels`, rounded to DN.
    pub fn frame(&self, cfa: Cfa, levels: &SceneLevels) -> Result<RawFrame> {
        let (h, w) = (self.spec.height, self.spec.width);
        let planes = plane_lut(cfa);
        let mut values = Vec::with_capacity(w * h);
        for row in 0..h {
            values.extend((0..w).map(|col| {
                let p = planes[row & 1][col & 1];
                self.sample(row, col, CHANNEL[p])
            }));
        }
        frame_from_values(&self.spec, cfa, levels, &values)
    }
}

/// Colour channel (0 R, 1 G, 2 B) of each packed plane R, G1, B, G2.
pub(crate) const CHANNEL: [usize; 4] = [0, 1, 2, 1];

/// Packed plane of each position in the 2x2 cell, `[row & 1][col & 1]`.
pub(crate) fn plane_lut(cfa: Cfa) -> [[usize; 2]; 2] {
    std::array::from_fn(|r| std::array::from_fn(|c| cfa.plane_at(r, c)))
}

/// Scale mosaic values in [0, 1] into `levels`, round to DN and wrap them in
/// a frame with the metadata every procedural scene carries.
pub(crate) fn frame_from_values(
    spec: &SceneSpec,
    cfa: Cfa,
    levels: &SceneLevels,
    values: &[f32],
) -> Result<RawFrame> {
    let (h, w) = (spec.height, spec.width);
    if levels.bits < bits_for(levels.white) || levels.bits > 16 {
        return Err(SceneError::BitsForWhite {
            bits: levels.bits,
            white: levels.white,
            needed: bits_for(levels.white),
        });
    }
    let range: [f32; 4] = std::array::from_fn(|p| levels.white as f32 - levels.black[p]);
    let planes = plane_lut(cfa);
    let mosaic = values
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            let p = planes[(i / w.max(1)) & 1][(i % w.max(1)) & 1];
            let dn = (levels.black[p] + v * range[p]).round();
            dn.clamp(0.0, u16::MAX as f32) as u16
        })
        .collect();
    let mut f = RawFrame::from_mosaic(w, h, mosaic, cfa, levels.black, levels.white)?;
    f.bits = levels.bits;
    // The scene is coloured as A7S2 camera RGB, so the frame carries the
    // A7S2 matrix and the white balance of a neutral: previews then look
    // right without any scene-specific knowledge.
    let n = a7s2_neutral();
    f.wb = Some([n[1] / n[0], 1.0, n[1] / n[2]]);
    f.color_matrices = vec![ColorMatrix {
        xyz_to_cam: A7S2_D65_MATRIX,
        illuminant: "D65".into(),
    }];
    f.make = "pgrf".into();
    f.model = format!("procedural {} (A7S2 colour)", spec.kind);
    Ok(f)
}

/// Dead leaves sampled through `cfa` while the discs are painted: each
/// pixel's one CFA channel is computed as its disc covers it, so no id map is
/// stored or read back. `store(row, col, plane, value)` takes each sample.
fn paint_mosaic(spec: &SceneSpec, cfa: Cfa, mut store: impl FnMut(usize, usize, usize, f32)) {
    let planes = plane_lut(cfa);
    let mut shades = Vec::new();
    deadleaves::paint(spec.width, spec.height, spec.seed, |_, d, table, pixels| {
        shades.clear();
        d.shade_batch(table, pixels, &mut shades);
        for (&[row, col], &s) in pixels.iter().zip(&shades) {
            let (row, col) = (row as usize, col as usize);
            let p = planes[row & 1][col & 1];
            store(row, col, p, d.value(CHANNEL[p], s));
        }
    });
}

/// R ramps left to right, G top to bottom, B falls along the diagonal: every
/// channel spans [0, 1] and no two are proportional, so a swapped plane or a
/// transposed phase shows up in a test.
#[inline]
fn gradient(sx: f32, sy: f32, sd: f32, row: usize, col: usize) -> [f32; 3] {
    [
        col as f32 / sx,
        row as f32 / sy,
        1.0 - (row + col) as f32 / sd,
    ]
}

/// `(height, width, 3)` linear camera RGB in [0, 1]; 1.0 means clipped.
pub fn render_rgb(spec: &SceneSpec) -> Array3<f32> {
    Scene::new(spec).rgb()
}

/// `(4, height / 2, width / 2)` normalised planes R, G1, B, G2 of an RGGB
/// sensor: what packing a noise-free frame of this scene gives, without the
/// rounding to DN. Use [`render_packed_cfa`] for another phase.
pub fn render_packed(spec: &SceneSpec) -> Array3<f32> {
    render_packed_cfa(spec, Cfa::Rggb)
}

/// [`render_packed`] for a sensor of phase `cfa`: the planes sit at different
/// mosaic positions, so across an edge their samples differ.
pub fn render_packed_cfa(spec: &SceneSpec, cfa: Cfa) -> Array3<f32> {
    match spec.kind {
        SceneKind::DeadLeaves => {
            let (ph, pw) = (spec.height / 2, spec.width / 2);
            let mut data = vec![0.0f32; 4 * ph * pw];
            paint_mosaic(spec, cfa, |row, col, p, v| {
                // A trailing odd row or column belongs to no 2x2 cell.
                let (i, j) = (row >> 1, col >> 1);
                if i < ph && j < pw {
                    data[(p * ph + i) * pw + j] = v;
                }
            });
            Array3::from_shape_vec((4, ph, pw), data).expect("4 * ph * pw samples")
        }
        SceneKind::Gradient => Scene::new(spec).packed(cfa),
    }
}

/// The scene as a noise-free RawFrame: mosaiced through `cfa`, scaled into
/// `levels` and rounded to DN, with A7S2 colour metadata and no ISO or
/// exposure (there was no capture).
pub fn render_frame(spec: &SceneSpec, cfa: Cfa, levels: &SceneLevels) -> Result<RawFrame> {
    match spec.kind {
        SceneKind::DeadLeaves => {
            let w = spec.width;
            let mut values = vec![0.0f32; w * spec.height];
            paint_mosaic(spec, cfa, |row, col, _, v| values[row * w + col] = v);
            frame_from_values(spec, cfa, levels, &values)
        }
        SceneKind::Gradient => Scene::new(spec).frame(cfa, levels),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kind_names_round_trip() {
        for k in SceneKind::ALL {
            assert_eq!(k.to_string().parse::<SceneKind>().unwrap(), k);
        }
        assert_eq!(
            "Dead_Leaves".parse::<SceneKind>().unwrap(),
            SceneKind::DeadLeaves
        );
        let e = "checker".parse::<SceneKind>().unwrap_err().to_string();
        assert!(e.contains("dead-leaves"), "{e}");
    }

    #[test]
    fn neutral_is_green_heavy() {
        let n = a7s2_neutral();
        assert_eq!(n[1], 1.0);
        assert!(n[0] > 0.2 && n[0] < 0.6, "{n:?}");
        assert!(n[2] > 0.5 && n[2] < 0.9, "{n:?}");
    }

    #[test]
    fn gradient_values_are_predictable() {
        let s = Scene::new(&SceneSpec::new(SceneKind::Gradient, 9, 5, 0));
        assert_eq!(s.sample(0, 0, 0), 0.0);
        assert_eq!(s.sample(0, 8, 0), 1.0);
        assert_eq!(s.sample(4, 3, 1), 1.0);
        assert_eq!(s.sample(0, 0, 2), 1.0);
        assert!((s.sample(2, 4, 0) - 0.5).abs() < 1e-6);
        assert!((s.sample(2, 1, 1) - 0.5).abs() < 1e-6);
        assert_eq!(s.sample(4, 8, 2), 0.0);
    }

    #[test]
    fn bad_levels_are_refused() {
        let spec = SceneSpec::new(SceneKind::Gradient, 8, 8, 0);
        let few_bits = SceneLevels {
            bits: 12,
            ..Default::default()
        };
        assert!(render_frame(&spec, Cfa::Rggb, &few_bits).is_err());
        let black_above_white = SceneLevels {
            black: [20000.0; 4],
            ..Default::default()
        };
        assert!(render_frame(&spec, Cfa::Rggb, &black_above_white).is_err());
    }
}
