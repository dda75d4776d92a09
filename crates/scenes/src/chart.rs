//! A test chart pgrf renders itself: the 24 ColorChecker patches, a neutral
//! ramp and a hue sweep, in linear camera RGB, mosaiced through a Bayer CFA
//! with realistic levels.
//!
//! It exists so the colour pipeline can be checked end to end without any
//! camera file (render -> DNG -> decode -> preview must give back the
//! published sRGB patch values), and so the README's first command has a frame
//! to work on before the procedural scenes of a later stage exist. It is
//! noise-free on purpose: noise belongs to the noise models.

use crate::error::Result;
use pgrf_raw::color::{Mat3, SRGB_TO_XYZ};
use pgrf_raw::{Cfa, ColorMatrix, RawFrame};

/// ColorChecker Classic patches as 8-bit sRGB (D65), row by row; the
/// commonly published BabelColor averages.
pub(crate) const COLORCHECKER_SRGB: [[u8; 3]; 24] = [
    [115, 82, 68],
    [194, 150, 130],
    [98, 122, 157],
    [87, 108, 67],
    [133, 128, 177],
    [103, 189, 170],
    [214, 126, 44],
    [80, 91, 166],
    [193, 90, 99],
    [94, 60, 108],
    [157, 188, 64],
    [224, 163, 46],
    [56, 61, 150],
    [70, 148, 73],
    [175, 54, 60],
    [231, 199, 31],
    [187, 86, 149],
    [8, 133, 161],
    [243, 243, 242],
    [200, 200, 200],
    [160, 160, 160],
    [122, 122, 121],
    [85, 85, 85],
    [52, 52, 52],
];

/// Sony A7S2 D65 ColorMatrix (XYZ -> camera), as published in camera
/// databases (dnglab/rawler's definition of the ILCE-7SM2).
pub const A7S2_D65_MATRIX: [[f32; 3]; 3] = [
    [0.5838, -0.143, -0.0246],
    [-0.3497, 1.1477, 0.2297],
    [-0.0748, 0.1885, 0.5778],
];

/// How to render the chart.
#[derive(Clone, Debug)]
pub struct ChartSpec {
    /// Frame width in pixels (even, as for any Bayer frame).
    pub width: usize,
    /// Frame height in pixels (even).
    pub height: usize,
    /// Bayer phase of the mosaic.
    pub cfa: Cfa,
    /// Black level in DN, the same for all four planes.
    pub black: f32,
    /// White (saturation) level in DN.
    pub white: u32,
    /// Fraction of the white-black range that a perfect white reflector
    /// reaches in the strongest camera channel (headroom below clipping).
    pub exposure: f32,
    /// ISO written into the frame's metadata (None: no ISO tag).
    pub iso: Option<u32>,
    /// Exposure time in seconds written into the frame's metadata.
    pub exposure_s: Option<f64>,
}

impl Default for ChartSpec {
    fn default() -> Self {
        ChartSpec {
            width: 1200,
            height: 800,
            cfa: Cfa::Rggb,
            black: 512.0,
            white: 16383,
            exposure: 0.5,
            iso: Some(100),
            exposure_s: Some(1.0 / 60.0),
        }
    }
}

/// sRGB 8-bit -> linear.
pub(crate) fn srgb_decode_u8(v: u8) -> f64 {
    let x = v as f64 / 255.0;
    if x <= 0.04045 {
        x / 12.92
    } else {
        ((x + 0.055) / 1.055).powf(2.4)
    }
}

/// Patch geometry: the chart occupies the top 70% of the frame in a 6x4 grid;
/// returns the (row, col) centre and half-size of patch `i` in pixels.
pub(crate) fn patch_box(spec: &ChartSpec, i: usize) -> (usize, usize, usize) {
    let chart_h = spec.height * 7 / 10;
    let cell_w = spec.width / 6;
    let cell_h = chart_h / 4;
    let (pr, pc) = (i / 6, i % 6);
    let half = (cell_w.min(cell_h) * 35 / 100).max(1);
    (pr * cell_h + cell_h / 2, pc * cell_w + cell_w / 2, half)
}

/// Camera response (A7S2 matrix) to linear sRGB: xyz_to_cam * srgb_to_xyz * rgb.
fn camera_rgb(rgb: [f64; 3]) -> [f64; 3] {
    let mul = |m: &Mat3, v: [f64; 3]| -> [f64; 3] {
        std::array::from_fn(|i| (0..3).map(|k| m[i][k] * v[k]).sum())
    };
    let x2c: Mat3 = std::array::from_fn(|i| std::array::from_fn(|j| A7S2_D65_MATRIX[i][j] as f64));
    mul(&x2c, mul(&SRGB_TO_XYZ, rgb))
}

/// Camera RGB of ColorChecker patch `i` (0..24), scaled so a perfect white
/// reflector's strongest channel is 1: the chart's colours for scenes that
/// place a chart themselves.
pub fn patch_camera_rgb(i: usize) -> [f32; 3] {
    let (_, peak) = white_response();
    camera_rgb(COLORCHECKER_SRGB[i].map(srgb_decode_u8)).map(|v| (v / peak) as f32)
}

/// Camera response to a perfect white reflector and its strongest channel.
fn white_response() -> ([f64; 3], f64) {
    let white = camera_rgb([1.0; 3]);
    (white, white.iter().cloned().fold(f64::MIN, f64::max))
}

/// White-balance multipliers (R, G, B) that make a D65 white neutral on
/// the A7S2: the camera's daylight neutral, green 1.
pub fn a7s2_daylight_wb() -> [f32; 3] {
    let (white_cam, _) = white_response();
    [
        (white_cam[1] / white_cam[0]) as f32,
        1.0,
        (white_cam[1] / white_cam[2]) as f32,
    ]
}

/// Render the chart as a RawFrame with the A7S2 colour matrix and the white
/// balance that makes its D65 white neutral.
pub fn render_chart(spec: &ChartSpec) -> Result<RawFrame> {
    let (_, peak) = white_response();
    let k = spec.exposure as f64 / peak;
    let wb = a7s2_daylight_wb();

    let (w, h) = (spec.width, spec.height);
    let chart_h = h * 7 / 10;
    let range = spec.white as f64 - spec.black as f64;
    let scene = |r: usize, c: usize| -> [f64; 3] {
        if r < chart_h {
            // Inside a patch box: its colour; elsewhere the chart's dark frame.
            for (i, patch) in COLORCHECKER_SRGB.iter().enumerate() {
                let (cr, cc, half) = patch_box(spec, i);
                if r.abs_diff(cr) <= half && c.abs_diff(cc) <= half {
                    return patch.map(srgb_decode_u8);
                }
            }
            [0.03, 0.03, 0.03]
        } else if r < chart_h + (h - chart_h) / 2 {
            // Neutral ramp, linear in light from 0 to 1.
            let t = c as f64 / (w.max(2) - 1) as f64;
            [t, t, t]
        } else {
            // Hue sweep at full saturation, half brightness.
            let t = c as f64 / w as f64 * 6.0;
            let x = 1.0 - ((t % 2.0) - 1.0).abs();
            let rgb = match t as usize {
                0 => [1.0, x, 0.0],
                1 => [x, 1.0, 0.0],
                2 => [0.0, 1.0, x],
                3 => [0.0, x, 1.0],
                4 => [x, 0.0, 1.0],
                _ => [1.0, 0.0, x],
            };
            rgb.map(|v| 0.5 * v)
        }
    };
    let mut mosaic = Vec::with_capacity(w * h);
    for r in 0..h {
        for c in 0..w {
            let cam = camera_rgb(scene(r, c));
            let v = cam[spec.cfa.color_at(r, c)] * k;
            let dn = spec.black as f64 + v.clamp(0.0, 1.0) * range;
            mosaic.push(dn.round() as u16);
        }
    }
    let mut f = RawFrame::from_mosaic(w, h, mosaic, spec.cfa, [spec.black; 4], spec.white)?;
    f.wb = Some(wb);
    f.color_matrices = vec![ColorMatrix {
        xyz_to_cam: A7S2_D65_MATRIX,
        illuminant: "D65".into(),
    }];
    f.iso = spec.iso;
    f.exposure_s = spec.exposure_s;
    f.make = "pgrf".into();
    f.model = "synthetic chart (A7S2 colour)".into();
    Ok(f)
}

/// The linear gain that maps the chart's exposure back to scene-referred
/// light (white reflector at 1.0 after white balance).
pub fn chart_display_gain(spec: &ChartSpec) -> f32 {
    // After white balance every channel of white equals the green response.
    let (white_cam, peak) = white_response();
    (peak / (spec.exposure as f64 * white_cam[1])) as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use pgrf_raw::{render_preview, PreviewOptions};

    #[test]
    fn chart_preview_reproduces_colorchecker_srgb() {
        for cfa in Cfa::ALL {
            let spec = ChartSpec {
                width: 600,
                height: 400,
                cfa,
                ..Default::default()
            };
            let f = render_chart(&spec).unwrap();
            let gain = chart_display_gain(&spec);
            let p = render_preview(
                &f,
                &PreviewOptions {
                    gain,
                    ..Default::default()
                },
            )
            .unwrap();
            assert!(p.warnings.is_empty());
            for (i, want) in COLORCHECKER_SRGB.iter().enumerate() {
                let (r, c, _) = patch_box(&spec, i);
                let px = &p.rgb[(r * p.width + c) * 3..(r * p.width + c) * 3 + 3];
                for k in 0..3 {
                    let got = px[k] * 255.0;
                    assert!(
                        (got - want[k] as f32).abs() < 1.0,
                        "{cfa} patch {} channel {k}: {got} vs {}",
                        i + 1,
                        want[k]
                    );
                }
            }
        }
    }

    #[test]
    fn chart_is_deterministic_and_within_levels() {
        let spec = ChartSpec {
            width: 120,
            height: 80,
            ..Default::default()
        };
        let a = render_chart(&spec).unwrap();
        let b = render_chart(&spec).unwrap();
        assert_eq!(a.mosaic, b.mosaic);
        assert!(a.mosaic.iter().all(|v| (512..=16383).contains(v)));
        // Headroom: the brightest sample stays below white (exposure 0.5 of range,
        // the ramp's end reaches exactly the chosen exposure).
        let max = *a.mosaic.iter().max().unwrap() as f32;
        assert!(max <= 512.0 + 0.5 * (16383.0 - 512.0) + 1.0, "{max}");
    }
}
