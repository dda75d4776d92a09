//! Colour cast: how far a restoration's colour has moved from the
//! reference's, as a mean CIELAB chroma difference over low-texture regions.
//!
//! PSNR and SSIM barely notice a small per-channel bias, yet a denoiser that
//! lifts blue by 1 % of white in the shadows turns a grey wall purple. The
//! figure measures exactly that, in ΔE*ab units (CIE76) with L* left out, so
//! a brightness error does not count as a cast.
//!
//! Definition ([`colour_cast`]), on packed `(4, H, W)` planes R, G1, B, G2
//! normalised to white = 1 (the result clamped to [0, 1], as for PSNR):
//!
//! 1. The planes are cut into blocks of [`BLOCK`] x [`BLOCK`] packed pixels
//!    (a trailing partial block is dropped).
//! 2. A block is *eligible* unless a reference value in it (any plane)
//!    reaches [`CLIPPED`] (clipped highlights have no colour to keep) or its
//!    reference mean green (G1 and G2) is below [`DARK`] (no colour to
//!    measure in the noise floor).
//! 3. A block is *low-texture* when the coefficient of variation of its
//!    reference green (population standard deviation over mean of its G1
//!    and G2 pixels) is at most the lower median of that value over the
//!    eligible blocks (the element `(n - 1) / 2` of them sorted): the
//!    smoother half of the eligible blocks, all of them when they tie.
//! 4. For each low-texture block, the means of R, G = (G1 + G2) / 2 and B of
//!    the reference and of the result are converted to CIELAB (D65 white,
//!    Y = 1 for the white-balanced camera white): camera RGB x the file's
//!    white balance (R, G, B multipliers, G = 1), camera -> linear sRGB with
//!    the matrix pgrf's preview uses (the inverse of the DNG ColorMatrix x
//!    sRGB->XYZ with rows normalised so white stays white, as dcraw), sRGB ->
//!    XYZ (IEC 61966-2-1), XYZ -> L*a*b* (CIE 1976).
//! 5. The figure is the mean over those blocks of the chroma difference
//!    sqrt(Δa*² + Δb*²) (result minus reference), and the signed means of
//!    Δa* (+: towards magenta, -: green) and Δb* (+: yellow, -: blue).
//!
//! Without a white balance the multipliers are 1; without a usable colour
//! matrix camera RGB is taken as linear sRGB (identity). [`Cast`] says which
//! applied. All sums are f64 in a fixed order, so the figure does not depend
//! on the thread count.

use super::input::pair;
use super::{MetricError, Result};
use ndarray::ArrayView3;

/// Side of the square blocks, packed pixels.
pub const BLOCK: usize = 16;
/// Reference values at or above this (normalised) mark a block as clipped.
pub const CLIPPED: f32 = 0.98;
/// Blocks whose reference mean green is below this are too dark to judge.
pub const DARK: f64 = 0.002;

/// The definition in one line, for headers of printed results.
pub const DEFINITION: &str = "colour cast = mean CIE76 chroma difference sqrt(da*^2 + db*^2) in dE*ab units \
(L* left out: brightness errors are no cast) of result vs reference over low-texture 16x16 packed-pixel blocks \
(reference green coefficient of variation <= its median over the blocks with no reference value >= 0.98 and \
reference mean green >= 0.002); block means R, (G1+G2)/2, B -> CIELAB D65 (white = 1) through each file's \
white balance and colour matrix (camera -> sRGB as pgrf preview -> XYZ); result clamped [0,1]; table: mean over \
images; CSV: also the signed da* (+ magenta) and db* (+ yellow)";

use pgrf_raw::color::{xyz_from_camera, Mat3, SRGB_TO_XYZ};

type Vec3 = [f64; 3];

/// The colour of a camera: what turns its white-balanced RGB into XYZ.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CameraColour {
    /// As-shot white-balance multipliers R, G, B (G = 1); None: all 1.
    pub wb: Option<[f32; 3]>,
    /// XYZ -> camera matrix (DNG ColorMatrix, D65 preferred); None: camera
    /// RGB is taken as linear sRGB.
    pub xyz_to_cam: Option<[[f32; 3]; 3]>,
}

impl CameraColour {
    /// The white balance and daylight colour matrix of a decoded frame.
    pub fn of(frame: &pgrf_raw::RawFrame) -> CameraColour {
        CameraColour {
            wb: frame.wb,
            xyz_to_cam: frame.color_matrix().map(|m| m.xyz_to_cam),
        }
    }
}

/// The colour-cast figure of one result (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cast {
    /// Mean chroma difference sqrt(Δa*² + Δb*²), ΔE*ab units.
    pub dab: f64,
    /// Mean signed Δa* (result - reference).
    pub da: f64,
    /// Mean signed Δb* (result - reference).
    pub db: f64,
    /// Low-texture blocks the means are over.
    pub blocks: usize,
    /// Eligible blocks (not clipped, not dark) they were chosen from.
    pub eligible: usize,
    /// Whether the file's white balance was used (else multipliers of 1).
    pub white_balance: bool,
    /// Whether the file's colour matrix was used (else camera RGB as sRGB).
    pub matrix: bool,
}

/// Per-block sums of one image: R, G (G1 + G2 halves), B means.
fn block_means(v: &[f32], dims: (usize, usize, usize), by: usize, bx: usize) -> Vec3 {
    let (_, h, w) = dims;
    let mean = |p: usize| -> f64 {
        let mut s = 0.0f64;
        for y in by * BLOCK..(by + 1) * BLOCK {
            let row = &v[(p * h + y) * w + bx * BLOCK..][..BLOCK];
            s += row.iter().map(|&x| x.clamp(0.0, 1.0) as f64).sum::<f64>();
        }
        s / (BLOCK * BLOCK) as f64
    };
    [mean(0), 0.5 * (mean(1) + mean(3)), mean(2)]
}

/// Reference block statistics: (eligible, green coefficient of variation).
fn block_texture(v: &[f32], dims: (usize, usize, usize), by: usize, bx: usize) -> (bool, f64) {
    let (c, h, w) = dims;
    let rows = |p: usize| {
        (by * BLOCK..(by + 1) * BLOCK).map(move |y| &v[(p * h + y) * w + bx * BLOCK..][..BLOCK])
    };
    let clipped = (0..c).any(|p| rows(p).flatten().any(|&x| x >= CLIPPED));
    let greens = || rows(1).chain(rows(3)).flatten().map(|&x| x as f64);
    let n = (2 * BLOCK * BLOCK) as f64;
    let mean = greens().sum::<f64>() / n;
    let var = greens().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n;
    let eligible = !clipped && mean >= DARK;
    (eligible, if eligible { var.sqrt() / mean } else { 0.0 })
}

fn mat_vec(m: &Mat3, v: Vec3) -> Vec3 {
    std::array::from_fn(|i| (0..3).map(|k| m[i][k] * v[k]).sum())
}

/// CIE 1976 L*a*b* of XYZ against the D65 white of sRGB (Y = 1).
fn lab(xyz: Vec3) -> Vec3 {
    let white = mat_vec(&SRGB_TO_XYZ, [1.0; 3]);
    let d = 6.0 / 29.0;
    let f = |t: f64| {
        if t > d * d * d {
            t.cbrt()
        } else {
            t / (3.0 * d * d) + 4.0 / 29.0
        }
    };
    let [fx, fy, fz] = [0, 1, 2].map(|i| f(xyz[i] / white[i]));
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

/// CIE 1976 L*a*b* (D65) of linear sRGB `rgb` (the primaries of
/// [`SRGB_TO_XYZ`]): what the cast is measured in, and what a render's
/// patches are compared in (`crates/cli/tests/photo_apps.rs`).
pub fn lab_of_linear_srgb(rgb: [f64; 3]) -> [f64; 3] {
    lab(mat_vec(&SRGB_TO_XYZ, rgb))
}

/// The colour cast of `result` against `reference`, both packed
/// `(4, H, W)` R, G1, B, G2 normalised to white = 1, in the camera colour
/// `colour` (see the module documentation for the definition). `Ok(None)`
/// when no block qualifies (image smaller than a block, or all clipped or
/// dark).
pub fn colour_cast(
    result: ArrayView3<f32>,
    reference: ArrayView3<f32>,
    colour: &CameraColour,
) -> Result<Option<Cast>> {
    let p = pair(result, reference)?;
    let dims = p.dims;
    if dims.0 != 4 {
        return Err(MetricError::InvalidOption(format!(
            "colour cast needs packed R, G1, B, G2 planes, got {} channels",
            dims.0
        )));
    }
    let xyz_matrix = colour.xyz_to_cam.as_ref().and_then(xyz_from_camera);
    let to_xyz = xyz_matrix.unwrap_or(SRGB_TO_XYZ);
    let wb = colour.wb.map(|w| w.map(f64::from)).unwrap_or([1.0; 3]);
    let lab_of = |rgb: Vec3| lab(mat_vec(&to_xyz, std::array::from_fn(|i| rgb[i] * wb[i])));

    let (nby, nbx) = (dims.1 / BLOCK, dims.2 / BLOCK);
    let blocks: Vec<(usize, usize)> = (0..nby)
        .flat_map(|by| (0..nbx).map(move |bx| (by, bx)))
        .collect();
    let texture: Vec<(bool, f64)> = blocks
        .iter()
        .map(|&(by, bx)| block_texture(&p.reference, dims, by, bx))
        .collect();
    let mut cvs: Vec<f64> = texture.iter().filter(|t| t.0).map(|t| t.1).collect();
    if cvs.is_empty() {
        return Ok(None);
    }
    cvs.sort_by(f64::total_cmp);
    let median = cvs[(cvs.len() - 1) / 2];
    let (mut dab, mut da, mut db, mut n) = (0.0f64, 0.0f64, 0.0f64, 0usize);
    for (&(by, bx), &(eligible, cv)) in blocks.iter().zip(&texture) {
        if !eligible || cv > median {
            continue;
        }
        let r = lab_of(block_means(&p.reference, dims, by, bx));
        let o = lab_of(block_means(&p.output, dims, by, bx));
        let (a, b) = (o[1] - r[1], o[2] - r[2]);
        dab += a.hypot(b);
        da += a;
        db += b;
        n += 1;
    }
    let k = n as f64;
    Ok(Some(Cast {
        dab: dab / k,
        da: da / k,
        db: db / k,
        blocks: n,
        eligible: cvs.len(),
        white_balance: colour.wb.is_some(),
        matrix: xyz_matrix.is_some(),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    /// CIELAB written out from the CIE definitions, independently of the
    /// module's: linear sRGB -> XYZ by the IEC matrix, D65 white
    /// (0.95047, 1, 1.08883).
    fn lab_of_srgb(rgb: [f64; 3]) -> [f64; 3] {
        let x = 0.4124564 * rgb[0] + 0.3575761 * rgb[1] + 0.1804375 * rgb[2];
        let y = 0.2126729 * rgb[0] + 0.7151522 * rgb[1] + 0.0721750 * rgb[2];
        let z = 0.0193339 * rgb[0] + 0.1191920 * rgb[1] + 0.9503041 * rgb[2];
        let f = |t: f64| {
            if t > 216.0 / 24389.0 {
                t.powf(1.0 / 3.0)
            } else {
                (24389.0 / 27.0 * t + 16.0) / 116.0
            }
        };
        let (fx, fy, fz) = (f(x / 0.95047), f(y), f(z / 1.08883));
        [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
    }

    #[test]
    fn the_one_line_definition_states_the_constants() {
        for want in [
            format!("{BLOCK}x{BLOCK}"),
            format!(">= {CLIPPED}"),
            format!(">= {DARK}"),
            "dE*ab".into(),
            "median".into(),
        ] {
            assert!(DEFINITION.contains(&want), "{want}");
        }
        assert!(!DEFINITION.contains('\n'));
    }

    #[test]
    fn lab_reference_points() {
        // sRGB red and white (linear), published L*a*b* (D65).
        let red = lab_of_srgb([1.0, 0.0, 0.0]);
        for (g, w) in red.iter().zip([53.2408, 80.0925, 67.2032]) {
            assert!((g - w).abs() < 2e-3, "{red:?}");
        }
        let m = lab(mat_vec(&SRGB_TO_XYZ, [1.0, 0.0, 0.0]));
        for (g, w) in m.iter().zip(red) {
            assert!((g - w).abs() < 1e-4, "{m:?}");
        }
        let white = lab(mat_vec(&SRGB_TO_XYZ, [1.0; 3]));
        assert!((white[0] - 100.0).abs() < 1e-9 && white[1].abs() < 1e-9 && white[2].abs() < 1e-9);
        // Dark values go through the linear segment.
        let dark = lab(mat_vec(&SRGB_TO_XYZ, [0.001, 0.002, 0.003]));
        let want = lab_of_srgb([0.001, 0.002, 0.003]);
        for (g, w) in dark.iter().zip(want) {
            assert!((g - w).abs() < 1e-6, "{dark:?} vs {want:?}");
        }
    }

    /// Packed image of 2x2 flat blocks, block k of camera colour `rgb[k]`.
    fn patches(rgb: &[[f32; 3]; 4]) -> Array3<f32> {
        Array3::from_shape_fn((4, 2 * BLOCK, 2 * BLOCK), |(p, y, x)| {
            let k = (y / BLOCK) * 2 + x / BLOCK;
            rgb[k][[0, 1, 2, 1][p]]
        })
    }

    const SRGB: [[f32; 3]; 4] = [
        [0.40, 0.30, 0.20],
        [0.10, 0.25, 0.45],
        [0.18, 0.18, 0.18],
        [0.05, 0.12, 0.03],
    ];
    const BIAS: [f32; 3] = [0.010, -0.004, 0.020];

    /// Expected (dab, da, db) over the four patches: Lab of the biased
    /// sRGB minus Lab of the sRGB, averaged.
    fn expected(srgb: &[[f32; 3]; 4], biased: &[[f32; 3]; 4]) -> [f64; 3] {
        let mut e = [0.0; 3];
        for (s, b) in srgb.iter().zip(biased) {
            let l0 = lab_of_srgb(s.map(f64::from));
            let l1 = lab_of_srgb(b.map(f64::from));
            let (a, bb) = (l1[1] - l0[1], l1[2] - l0[2]);
            e[0] += a.hypot(bb) / 4.0;
            e[1] += a / 4.0;
            e[2] += bb / 4.0;
        }
        e
    }

    #[test]
    fn known_bias_on_flat_patches_identity_colour() {
        let reference = patches(&SRGB);
        let biased: [[f32; 3]; 4] = SRGB.map(|c| std::array::from_fn(|i| c[i] + BIAS[i]));
        let result = patches(&biased);
        let c = colour_cast(result.view(), reference.view(), &CameraColour::default())
            .unwrap()
            .unwrap();
        assert_eq!((c.blocks, c.eligible), (4, 4));
        assert!(!c.matrix && !c.white_balance);
        let want = expected(&SRGB, &biased);
        for (g, w) in [c.dab, c.da, c.db].iter().zip(want) {
            assert!((g - w).abs() < 1e-3, "{c:?} vs {want:?}");
        }
        // A bias towards blue and red: magenta-ish and bluish, i.e. b* < 0.
        assert!(c.dab > 1.0 && c.db < 0.0, "{c:?}");
    }

    #[test]
    fn known_bias_through_white_balance_and_matrix() {
        // A camera whose XYZ->camera matrix is XYZ->sRGB: camera-from-sRGB
        // is the identity, so white-balanced camera RGB is linear sRGB.
        let xyz_to_srgb = [
            [3.240_454_2, -1.537_138_5, -0.498_531_4],
            [-0.969_266, 1.876_010_8, 0.041_556],
            [0.055_643_4, -0.204_025_9, 1.057_225_2],
        ];
        let wb = [2.0f32, 1.0, 1.5];
        let colour = CameraColour {
            wb: Some(wb),
            xyz_to_cam: Some(xyz_to_srgb),
        };
        let cam: [[f32; 3]; 4] = SRGB.map(|c| std::array::from_fn(|i| c[i] / wb[i]));
        let cam_biased: [[f32; 3]; 4] = cam.map(|c| std::array::from_fn(|i| c[i] + BIAS[i]));
        let c = colour_cast(patches(&cam_biased).view(), patches(&cam).view(), &colour)
            .unwrap()
            .unwrap();
        assert!(c.matrix && c.white_balance);
        // In sRGB the bias is multiplied by the white balance.
        let srgb_of = |v: &[[f32; 3]; 4]| -> [[f32; 3]; 4] {
            v.map(|c| std::array::from_fn(|i| c[i] * wb[i]))
        };
        let want = expected(&srgb_of(&cam), &srgb_of(&cam_biased));
        for (g, w) in [c.dab, c.da, c.db].iter().zip(want) {
            assert!((g - w).abs() < 1e-3, "{c:?} vs {want:?}");
        }
    }

    #[test]
    fn equal_images_have_no_cast() {
        let reference = Array3::from_shape_fn((4, 48, 40), |(p, y, x)| {
            0.05 + 0.2 * p as f32 + 0.003 * ((y * 7 + x * 3) % 11) as f32
        });
        let colour = CameraColour {
            wb: Some([2.4, 1.0, 1.7]),
            xyz_to_cam: Some([
                [0.6461, -0.1164, -0.0857],
                [-0.3825, 1.1597, 0.2534],
                [-0.0416, 0.154, 0.6039],
            ]),
        };
        let c = colour_cast(reference.view(), reference.view(), &colour)
            .unwrap()
            .unwrap();
        assert_eq!((c.dab, c.da, c.db), (0.0, 0.0, 0.0));
        // 48x40 packed: 3x2 whole blocks, the rest dropped.
        assert_eq!(c.eligible, 6);
        assert!(c.blocks >= 3 && c.matrix && c.white_balance);
    }

    #[test]
    fn clipped_dark_and_textured_blocks_are_left_out() {
        // 4x4 blocks: 8 flat, 6 textured, 1 clipped, 1 dark. The result
        // differs wildly from the reference everywhere but on the flat ones.
        let kind = |k: usize| match k {
            0..=7 => "flat",
            8..=13 => "texture",
            14 => "clipped",
            _ => "dark",
        };
        let reference = Array3::from_shape_fn((4, 4 * BLOCK, 4 * BLOCK), |(p, y, x)| {
            let k = (y / BLOCK) * 4 + x / BLOCK;
            // G1 and G2 equal, so a flat block has no green variation at all.
            let base = 0.2 + 0.02 * k as f32 + 0.05 * [0.0, 1.0, 2.0, 1.0][p];
            match kind(k) {
                "flat" => base,
                "texture" => base * if (x + y) % 2 == 0 { 0.5 } else { 1.5 },
                "clipped" => {
                    if (y, x) == (3 * BLOCK + 5, 2 * BLOCK + 7) {
                        0.99
                    } else {
                        0.3
                    }
                }
                _ => 0.001,
            }
        });
        let result = Array3::from_shape_fn(reference.dim(), |(p, y, x)| {
            let k = (y / BLOCK) * 4 + x / BLOCK;
            let v = reference[[p, y, x]];
            if kind(k) == "flat" {
                v
            } else if p == 2 {
                (v + 0.3).min(1.0)
            } else {
                v * 0.5
            }
        });
        let c = colour_cast(result.view(), reference.view(), &CameraColour::default())
            .unwrap()
            .unwrap();
        assert_eq!((c.blocks, c.eligible), (8, 14));
        assert_eq!((c.dab, c.da, c.db), (0.0, 0.0, 0.0));
        // The same difference on a flat block does count.
        let mut r2 = result.clone();
        r2[[2, 0, 0]] += 0.5;
        let c2 = colour_cast(r2.view(), reference.view(), &CameraColour::default())
            .unwrap()
            .unwrap();
        assert!(c2.dab > 0.0 && c2.db < 0.0, "{c2:?}");
        // Nothing to judge: all clipped.
        let white = Array3::from_elem((4, 32, 32), 1.0f32);
        assert_eq!(
            colour_cast(white.view(), white.view(), &CameraColour::default()).unwrap(),
            None
        );
        assert!(colour_cast(
            white.slice(ndarray::s![..3, .., ..]),
            white.slice(ndarray::s![..3, .., ..]),
            &CameraColour::default()
        )
        .is_err());
    }
}
