//! What one dead leaf looks like: colour, shading and texture, and how the
//! scene's palette draws them.
//!
//! Shading uses only +, *, floor (built from a truncating cast) and max, and
//! every path that evaluates a leaf (one pixel at a time, or a batch of
//! pixels with the texture branch hoisted out) runs the same arithmetic, so
//! all renderers agree bit for bit.

use super::cover::floor32;
use rand::Rng;
use rand_xoshiro::Xoshiro256PlusPlus;

/// Luminance decades spanned by ordinary (non-highlight) regions.
const DECADES: f32 = 1.8;
/// Luminance of the brightest ordinary region in the strongest channel:
/// headroom so that only highlights clip.
const PEAK: f32 = 0.8;
/// Highlights are small (speculars, lamps): limiting them to small discs
/// bounds the saturated share of any one scene, which a large clipped disc
/// would otherwise dominate.
const HIGHLIGHT_MAX_RADIUS_FRACTION: f64 = 0.03;
const HIGHLIGHT_PROBABILITY: f32 = 0.04;

/// Side of the value-noise lattice table. Each textured disc reads it at its
/// own offset, so textures differ between discs; the table repeats only every
/// 128 lattice cells (at least 190 pixels), more than a textured disc spans
/// in most scenes.
const LATTICE: usize = 128;

/// Fine texture inside a region. Low amplitude: it is there so flat regions
/// are not perfectly flat (a denoiser that smooths everything must lose
/// PSNR), not to dominate the image.
#[derive(Clone, Copy, Debug)]
enum Texture {
    Flat,
    /// A grating; `kx, ky` in cycles per pixel.
    Grating {
        kx: f32,
        ky: f32,
        phase: f32,
        amp: f32,
    },
    /// Bilinear value noise on a lattice of `1 / inv_cell` pixels, read
    /// from the scene's table at offset (ox, oy).
    Noise {
        inv_cell: f32,
        amp: f32,
        ox: i32,
        oy: i32,
    },
}

/// One visible region: a disc's colour, its linear shading and texture.
#[derive(Clone, Copy, Debug)]
pub(super) struct Disc {
    pub(super) cx: f32,
    pub(super) cy: f32,
    /// Only the tests read it (occlusion and size statistics).
    #[cfg_attr(not(test), allow(dead_code))]
    pub(super) r: f32,
    base: [f32; 3],
    gx: f32,
    gy: f32,
    tex: Texture,
}

/// Parabolic approximation of sin(2 pi t): smooth (C1), branch-free, no
/// libm call, and the same bits on every platform.
#[inline(always)]
fn psin(t: f32) -> f32 {
    let w = t - floor32(t + 0.5);
    8.0 * w * (1.0 - 2.0 * w.abs())
}

#[inline(always)]
fn value_noise(table: &[f32], x: f32, y: f32, ox: i32, oy: i32) -> f32 {
    let (fx, fy) = (floor32(x), floor32(y));
    let (ix, iy) = (fx as i32 + ox, fy as i32 + oy);
    let (tx, ty) = (x - fx, y - fy);
    // Smoothstep weights: no creases along lattice lines.
    let (sx, sy) = (tx * tx * (3.0 - 2.0 * tx), ty * ty * (3.0 - 2.0 * ty));
    let m = LATTICE as i32 - 1;
    let at = |i: i32, j: i32| table[(j & m) as usize * LATTICE + (i & m) as usize];
    let (a, b) = (at(ix, iy), at(ix + 1, iy));
    let (c, d) = (at(ix, iy + 1), at(ix + 1, iy + 1));
    let top = a + sx * (b - a);
    let bottom = c + sx * (d - c);
    top + sy * (bottom - top)
}

impl Disc {
    #[inline(always)]
    fn offset(&self, row: u32, col: u32) -> (f32, f32) {
        (col as f32 - self.cx, row as f32 - self.cy)
    }

    /// Linear shading times a texture factor, never negative.
    #[inline(always)]
    fn combine(&self, dx: f32, dy: f32, tex: f32) -> f32 {
        ((1.0 + self.gx * dx + self.gy * dy) * tex).max(0.0)
    }

    /// Shading at mosaic pixel (row, col).
    #[inline]
    pub(super) fn shade(&self, table: &[f32], row: u32, col: u32) -> f32 {
        let (dx, dy) = self.offset(row, col);
        let tex = match self.tex {
            Texture::Flat => 1.0,
            Texture::Grating { kx, ky, phase, amp } => 1.0 + amp * psin(kx * dx + ky * dy + phase),
            Texture::Noise {
                inv_cell,
                amp,
                ox,
                oy,
            } => 1.0 + amp * value_noise(table, dx * inv_cell, dy * inv_cell, ox, oy),
        };
        self.combine(dx, dy, tex)
    }

    /// `shade` for many pixels of this disc, appended to `out`: the texture
    /// branch is taken once per disc instead of once per pixel, which is
    /// what makes the fused packed renderer fast.
    pub(super) fn shade_batch(&self, table: &[f32], pixels: &[[u32; 2]], out: &mut Vec<f32>) {
        let at = |&[row, col]: &[u32; 2]| self.offset(row, col);
        match self.tex {
            Texture::Flat => out.extend(pixels.iter().map(|p| {
                let (dx, dy) = at(p);
                self.combine(dx, dy, 1.0)
            })),
            Texture::Grating { kx, ky, phase, amp } => out.extend(pixels.iter().map(|p| {
                let (dx, dy) = at(p);
                self.combine(dx, dy, 1.0 + amp * psin(kx * dx + ky * dy + phase))
            })),
            Texture::Noise {
                inv_cell,
                amp,
                ox,
                oy,
            } => out.extend(pixels.iter().map(|p| {
                let (dx, dy) = at(p);
                let n = value_noise(table, dx * inv_cell, dy * inv_cell, ox, oy);
                self.combine(dx, dy, 1.0 + amp * n)
            })),
        }
    }

    /// Channel `c` given the shading: clipped to [0, 1] like a sensor.
    #[inline(always)]
    pub(super) fn value(&self, c: usize, shade: f32) -> f32 {
        (self.base[c] * shade).clamp(0.0, 1.0)
    }
}

/// Colour parameters shared by every region of a scene.
pub(super) struct Palette {
    /// Camera response to a neutral surface (A7S2 under D65, tinted per
    /// scene), strongest channel 1: camera RGB is green-heavy, and raw
    /// training data should be too.
    neutral: [f32; 3],
    highlight_r: f64,
}

fn uniform(rng: &mut Xoshiro256PlusPlus, lo: f32, hi: f32) -> f32 {
    lo + (hi - lo) * rng.random::<f32>()
}

impl Palette {
    pub(super) fn new(rng: &mut Xoshiro256PlusPlus, width: usize, height: usize) -> Self {
        let cam = super::a7s2_neutral();
        // A mild random illuminant tint so white balance is not a constant
        // the network could memorise.
        let tint = [
            uniform(rng, -0.2, 0.2).exp(),
            1.0,
            uniform(rng, -0.2, 0.2).exp(),
        ];
        let n: [f32; 3] = std::array::from_fn(|c| cam[c] * tint[c]);
        let max = n.iter().cloned().fold(0.0f32, f32::max);
        Palette {
            neutral: n.map(|v| v / max),
            highlight_r: HIGHLIGHT_MAX_RADIUS_FRACTION * width.max(height) as f64,
        }
    }

    pub(super) fn disc(&self, rng: &mut Xoshiro256PlusPlus, r: f64, cx: f64, cy: f64) -> Disc {
        let highlight = r <= self.highlight_r && rng.random::<f32>() < HIGHLIGHT_PROBABILITY;
        // Chroma: log-uniform channel factors with a random spread, from grey
        // to moderately saturated, geometric mean 1 so `lum` stays luminance.
        let spread = uniform(rng, 0.0, 0.6);
        let logs: [f32; 3] = std::array::from_fn(|_| spread * uniform(rng, -1.0, 1.0));
        let mean = (logs[0] + logs[1] + logs[2]) / 3.0;
        let chroma = logs.map(|l| (l - mean).exp());
        let mut base: [f32; 3] = std::array::from_fn(|c| self.neutral[c] * chroma[c]);
        let peak = base.iter().cloned().fold(0.0f32, f32::max);
        let lum = if highlight {
            // Strongest channel between just clipping and well past it.
            uniform(rng, 1.0, 3.0) / peak
        } else {
            PEAK * 10f32.powf(-DECADES * rng.random::<f32>()) / peak
        };
        base.iter_mut().for_each(|b| *b *= lum);

        // Linear shading across the disc: +-s at its rim, like light falling
        // off over a curved or tilted surface.
        let s = uniform(rng, 0.0, 0.6);
        let theta = uniform(rng, 0.0, std::f32::consts::TAU);
        let (gx, gy) = (s * theta.cos() / r as f32, s * theta.sin() / r as f32);

        let pick = rng.random::<f32>();
        let tex = if pick < 0.3 {
            let period = 2.5 * 2f32.powf(uniform(rng, 0.0, 3.0));
            let dir = uniform(rng, 0.0, std::f32::consts::TAU);
            Texture::Grating {
                kx: dir.cos() / period,
                ky: dir.sin() / period,
                phase: rng.random::<f32>(),
                amp: uniform(rng, 0.03, 0.15),
            }
        } else if pick < 0.55 {
            Texture::Noise {
                inv_cell: 1.0 / (1.5 * 2f32.powf(uniform(rng, 0.0, 2.5))),
                amp: uniform(rng, 0.05, 0.25),
                ox: rng.random_range(0..LATTICE as i32),
                oy: rng.random_range(0..LATTICE as i32),
            }
        } else {
            Texture::Flat
        };
        Disc {
            cx: cx as f32,
            cy: cy as f32,
            r: r as f32,
            base,
            gx,
            gy,
            tex,
        }
    }
}

/// The value-noise lattice of one scene: `LATTICE` x `LATTICE` values in
/// [-1, 1].
pub(super) fn lattice_table(rng: &mut Xoshiro256PlusPlus) -> Vec<f32> {
    (0..LATTICE * LATTICE)
        .map(|_| uniform(rng, -1.0, 1.0))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn parabolic_sine_tracks_sine() {
        for i in 0..1000 {
            let t = i as f32 / 137.0 - 3.0;
            let err = (psin(t) - (std::f32::consts::TAU * t).sin()).abs();
            assert!(err < 0.06, "t={t} err={err}");
        }
    }

    #[test]
    fn value_noise_is_bounded_and_continuous() {
        let table = lattice_table(&mut Xoshiro256PlusPlus::seed_from_u64(1));
        let mut prev = value_noise(&table, -5.0, 0.3, 7, 100);
        for i in 1..2000 {
            let x = -5.0 + i as f32 * 0.005;
            let v = value_noise(&table, x, 0.3, 7, 100);
            assert!((-1.0..=1.0).contains(&v));
            assert!((v - prev).abs() < 0.02, "jump at {x}: {prev} -> {v}");
            prev = v;
        }
    }

    #[test]
    fn batch_shading_equals_per_pixel_shading() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        let table = lattice_table(&mut rng);
        let palette = Palette::new(&mut rng, 200, 200);
        let pixels: Vec<[u32; 2]> = (0..400).map(|i| [i / 20 + 90, i % 20 + 37]).collect();
        let mut kinds = [0; 3];
        for _ in 0..60 {
            let d = palette.disc(&mut rng, 12.0, 100.0, 45.0);
            kinds[match d.tex {
                Texture::Flat => 0,
                Texture::Grating { .. } => 1,
                Texture::Noise { .. } => 2,
            }] += 1;
            let mut batch = Vec::new();
            d.shade_batch(&table, &pixels, &mut batch);
            for (&[r, c], b) in pixels.iter().zip(batch) {
                assert_eq!(b.to_bits(), d.shade(&table, r, c).to_bits());
            }
        }
        assert!(kinds.iter().all(|&k| k > 0), "{kinds:?}");
    }
}
