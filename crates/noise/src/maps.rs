//! Per-pixel noise maps, the paper's key idea: every pixel has its own offset,
//! read-noise level and dark current, measured by calibration. The same type
//! carries global values (the "noD" ablation, or a profile without a
//! calibration) without allocating full-size arrays.

use crate::error::{NoiseError, Result};
use crate::profile::DarkLaw;
use ndarray::Array3;
use std::sync::Arc;

/// One map: a single value, one value per packed plane, or one per pixel in
/// packed layout `(4, H/2, W/2)`.
#[derive(Clone, Debug)]
pub enum Map {
    /// The same value at every pixel.
    Scalar(f32),
    /// One value per packed plane, in R, G1, B, G2 order.
    Plane([f32; 4]),
    /// One value per pixel, packed `(4, H/2, W/2)`; shared, not copied, by clones.
    Pixel(Arc<Array3<f32>>),
}

impl Map {
    #[inline(always)]
    pub(crate) fn at(&self, plane: usize, flat_in_plane: usize) -> f32 {
        match self {
            Map::Scalar(v) => *v,
            Map::Plane(v) => v[plane],
            Map::Pixel(a) => {
                let s = a.as_slice().expect("maps are standard layout");
                s[plane * (s.len() / 4) + flat_in_plane]
            }
        }
    }

    /// Row of a per-pixel map, or None for scalar/plane maps.
    #[inline]
    pub(crate) fn row(&self, plane: usize, i: usize, pw: usize) -> Option<&[f32]> {
        match self {
            Map::Pixel(a) => {
                let s = a.as_slice().expect("maps are standard layout");
                let ph = s.len() / 4 / pw;
                let start = (plane * ph + i) * pw;
                Some(&s[start..start + pw])
            }
            _ => None,
        }
    }

    /// The global value that replaces this map in the "noD" ablation: its mean
    /// per plane.
    pub(crate) fn global(&self) -> Map {
        match self {
            Map::Pixel(a) => {
                let m: [f32; 4] = std::array::from_fn(|p| {
                    let plane = a.index_axis(ndarray::Axis(0), p);
                    (plane.iter().map(|&v| v as f64).sum::<f64>() / plane.len() as f64) as f32
                });
                Map::Plane(m)
            }
            other => other.clone(),
        }
    }

    /// The window `(y, x, h, w)` of a per-pixel map (packed coordinates);
    /// scalar and per-plane maps are unchanged. Training crops need the maps
    /// of the sensor region the crop stands for.
    pub(crate) fn crop(&self, y: usize, x: usize, h: usize, w: usize) -> Result<Map> {
        match self {
            Map::Pixel(a) => {
                let (ph, pw) = (a.shape()[1], a.shape()[2]);
                if y + h > ph || x + w > pw {
                    return Err(NoiseError::CropOutside {
                        at: (y, x),
                        size: (h, w),
                        map: (ph, pw),
                    });
                }
                let v = a.slice(ndarray::s![.., y..y + h, x..x + w]);
                Ok(Map::Pixel(Arc::new(v.as_standard_layout().into_owned())))
            }
            other => Ok(other.clone()),
        }
    }

    /// Packed size `(H/2, W/2)` of a per-pixel map.
    pub(crate) fn pixel_shape(&self) -> Option<(usize, usize)> {
        match self {
            Map::Pixel(a) => Some((a.shape()[1], a.shape()[2])),
            _ => None,
        }
    }

    fn check(&self, name: &'static str, shape: (usize, usize), nonneg: bool) -> Result<()> {
        let bad = |v: f32| !v.is_finite() || (nonneg && v < 0.0);
        let must = if nonneg { "finite and >= 0" } else { "finite" };
        match self {
            Map::Scalar(v) if bad(*v) => Err(NoiseError::Setting {
                name,
                must,
                value: *v,
            }),
            Map::Plane(v) if v.iter().any(|x| bad(*x)) => Err(NoiseError::PlaneSetting {
                name,
                must,
                value: *v,
            }),
            Map::Pixel(a) => {
                if a.shape() != [4, shape.0, shape.1] {
                    return Err(NoiseError::MapShape {
                        map: name,
                        shape: a.shape().to_vec(),
                        packed: shape,
                    });
                }
                if !a.is_standard_layout() {
                    return Err(NoiseError::MapLayout { map: name });
                }
                Ok(())
            }
            _ => Ok(()),
        }
    }
}

fn check_fp(min_fp: f32) -> Result<()> {
    if min_fp < -1.0 {
        return Err(NoiseError::FixedPatternBelow { min: min_fp });
    }
    Ok(())
}

/// The per-pixel description of a sensor the PGRF model needs.
#[derive(Clone, Debug)]
pub struct PixelMaps {
    /// Fixed-pattern offset of the dark level, DN (bias frames' mean - black).
    pub bias: Map,
    /// Source-follower read-noise standard deviation (sigma_r of N_r), DN.
    pub sigma_read: Map,
    /// Dark-current rate, electrons per sqrt(s) or per s (see `dark_law`):
    /// N_RS = K Poisson(rate x law(t)).
    pub dark_rate: Map,
    /// Fixed-pattern deviation N_FP multiplying the dark signal: D = N_RS (1 + N_FP).
    pub n_fp: Map,
    /// How the dark signal grows with exposure time (the unit of `dark_rate`).
    pub dark_law: DarkLaw,
}

impl PixelMaps {
    /// Shapes against the packed image `(H/2, W/2)`, and scalar/per-plane
    /// values. Constant time, because the sampler calls it on every frame;
    /// per-pixel values are scanned once where maps are loaded
    /// ([`Self::check_values`]) and non-finite results are caught by the sampler.
    pub(crate) fn check(&self, shape: (usize, usize)) -> Result<()> {
        self.bias.check("bias", shape, false)?;
        self.sigma_read.check("sigma_read", shape, true)?;
        self.dark_rate.check("dark_rate", shape, true)?;
        self.n_fp.check("n_fp", shape, false)?;
        let min_fp = match &self.n_fp {
            Map::Scalar(v) => *v,
            Map::Plane(v) => v.iter().cloned().fold(f32::MAX, f32::min),
            Map::Pixel(_) => 0.0,
        };
        check_fp(min_fp)
    }

    /// Every per-pixel value: finite, inside what a sensor can have (so
    /// that scaling by a gain and an exposure stays finite: a dark rate of
    /// 3e38 passed "finite" and made the dark shading infinite), and
    /// 1 + N_FP >= 0 (or the dark signal would turn negative).
    pub fn check_values(&self) -> Result<()> {
        // Bias and read noise in DN are within a 16-bit range; a dark rate
        // (electrons per s or per sqrt(s)) of a million saturates any pixel
        // in a millisecond; N_FP is a relative deviation.
        const DN: f32 = 65535.0;
        for (name, m, lo, hi) in [
            ("bias", &self.bias, -DN, DN),
            ("sigma_read", &self.sigma_read, 0.0, DN),
            ("dark_rate", &self.dark_rate, 0.0, 1e6),
            ("n_fp", &self.n_fp, -1e3, 1e3),
        ] {
            if let Map::Pixel(a) = m {
                if let Some((pos, v)) = a.iter().enumerate().find(|(_, v)| !(lo..=hi).contains(*v))
                {
                    return Err(NoiseError::MapValue {
                        map: name,
                        value: *v,
                        index: pos,
                        lo,
                        hi,
                    });
                }
            }
        }
        if let Map::Pixel(a) = &self.n_fp {
            check_fp(a.iter().cloned().fold(f32::MAX, f32::min))?;
        }
        Ok(())
    }

    /// The maps of the packed window `(y, x, h, w)`.
    pub fn crop(&self, y: usize, x: usize, h: usize, w: usize) -> Result<PixelMaps> {
        Ok(PixelMaps {
            bias: self.bias.crop(y, x, h, w)?,
            sigma_read: self.sigma_read.crop(y, x, h, w)?,
            dark_rate: self.dark_rate.crop(y, x, h, w)?,
            n_fp: self.n_fp.crop(y, x, h, w)?,
            dark_law: self.dark_law,
        })
    }

    /// Packed size of the per-pixel maps, if any map is per pixel.
    pub fn pixel_shape(&self) -> Option<(usize, usize)> {
        [&self.bias, &self.sigma_read, &self.dark_rate, &self.n_fp]
            .iter()
            .find_map(|m| m.pixel_shape())
    }

    /// Global ("noD") version: each map replaced by its per-plane mean.
    pub fn global(&self) -> PixelMaps {
        PixelMaps {
            bias: self.bias.global(),
            sigma_read: self.sigma_read.global(),
            dark_rate: self.dark_rate.global(),
            n_fp: self.n_fp.global(),
            dark_law: self.dark_law,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crops_take_the_window_and_refuse_to_leave_the_map() {
        let a = Array3::from_shape_fn((4, 6, 8), |(p, i, j)| (p * 100 + i * 10 + j) as f32);
        let m = PixelMaps {
            bias: Map::Pixel(Arc::new(a)),
            sigma_read: Map::Scalar(2.0),
            dark_rate: Map::Plane([1.0, 2.0, 3.0, 4.0]),
            n_fp: Map::Scalar(0.0),
            dark_law: DarkLaw::Sqrt,
        };
        assert_eq!(m.pixel_shape(), Some((6, 8)));
        let c = m.crop(2, 3, 3, 4).unwrap();
        assert_eq!(c.pixel_shape(), Some((3, 4)));
        assert_eq!(c.bias.at(0, 0), 23.0);
        assert_eq!(c.bias.at(3, 3 * 4 - 1), 346.0);
        assert_eq!(c.sigma_read.at(1, 5), 2.0);
        c.check((3, 4)).unwrap();
        assert!(m.crop(4, 0, 3, 4).is_err());
    }
}
