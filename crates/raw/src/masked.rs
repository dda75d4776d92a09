//! The sensor's masked (optical-black) pixels: the black level measured
//! where no light reaches, per plane, rather than read from metadata.
//!
//! A camera's metadata black level is a constant of the model; the offset a
//! given capture actually carries drifts with temperature, gain and time
//! (ELD measured a per-capture colour bias of a few DN on the A7S2), and
//! after amplifying a dark capture x100 a 2 DN error is a visibly lifted,
//! tinted black. Sensors shield a border of pixels from light for exactly
//! this: their mean is the offset of that capture. Raw converters subtract
//! it (LibRaw's `cblack` from masked pixels, Adobe's DNGs declare the areas
//! in `MaskedAreas`). pgrf measures it on decoding ([`Masked`]) and
//! `pgrf enhance` subtracts it from an uncalibrated frame.
//!
//! The measure is a sigma-clipped mean per plane: the median and the
//! median absolute deviation locate the bulk, pixels further than 5 robust
//! standard deviations (hot pixels, which shielding does not stop) are
//! left out, and the rest are averaged: the mean, not the median, because
//! the offset the network must remove is the mean of the read noise, and
//! a 14-bit DN quantises a median to whole values.

/// Fewest pixels per plane for a measure: below this the mean of the
/// masked pixels (read noise of a few DN) is no better than the metadata.
pub const MIN_PIXELS: usize = 256;

/// Where the masked area was declared.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MaskedSource {
    /// The DNG's `MaskedAreas` tag.
    DngTag,
    /// rawler's camera data (the masked border of the camera's readout,
    /// e.g. Canon's CR2).
    Camera,
}

impl MaskedSource {
    /// How the source is named on a file's line.
    pub fn describe(self) -> &'static str {
        match self {
            MaskedSource::DngTag => "the DNG's MaskedAreas",
            MaskedSource::Camera => "the camera's masked border",
        }
    }
}

/// Masked columns left of the visible area, full visible height: the
/// layout `pgrf synth --masked-columns` writes, kept so that a DNG written
/// from the frame carries them again.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MaskedStrip {
    /// Columns (even, so the strip does not shift the CFA phase).
    pub columns: usize,
    /// Row-major samples in DN, `columns * height`.
    pub values: Vec<u16>,
}

/// The black level measured on a frame's masked pixels.
#[derive(Clone, Debug, PartialEq)]
pub struct Masked {
    /// Sigma-clipped mean per packed plane (R, G1, B, G2), DN.
    pub level: [f32; 4],
    /// Pixels averaged, the fewest of the four planes.
    pub pixels: usize,
    /// Where the area was declared.
    pub source: MaskedSource,
    /// The pixels themselves when they are a strip left of the visible
    /// area ([`MaskedStrip`]).
    pub strip: Option<MaskedStrip>,
}

impl Masked {
    /// The measure of a strip of masked columns left of a visible area
    /// `height` rows high whose first pixel has the phase `cfa`; None when it
    /// is too small to measure ([`MIN_PIXELS`] per plane).
    pub fn of_strip(strip: MaskedStrip, height: usize, cfa: crate::Cfa) -> Option<Masked> {
        let c = strip.columns;
        let area = Area {
            top: 0,
            left: 0,
            bottom: height,
            right: c,
        };
        // The visible area begins right of the strip (no pixels of it are
        // here); the strip's columns are even, so its phase is the area's.
        let (level, pixels) = measure(
            &strip.values,
            (height, c),
            &[area],
            (0, c, height, 0),
            cfa.offsets(),
        )?;
        Some(Masked {
            level,
            pixels,
            source: MaskedSource::DngTag,
            strip: Some(strip),
        })
    }
}

/// Four per-plane levels as "a/b/c/d" with two decimals, as the lines that
/// report a masked level print them.
pub fn levels_text(v: [f32; 4]) -> String {
    v.map(|x| format!("{x:.2}")).join("/")
}

/// One masked rectangle of the readout, half-open: rows `top..bottom`,
/// columns `left..right` (the DNG tag's order).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Area {
    /// First row.
    pub top: usize,
    /// First column.
    pub left: usize,
    /// One past the last row.
    pub bottom: usize,
    /// One past the last column.
    pub right: usize,
}

/// The masked pixels of `areas` in a readout of `size` (height, width),
/// sorted into the packed planes of a visible area starting at `origin`
/// (row, col) whose first pixel's plane offsets are `offsets`
/// ([`crate::Cfa::offsets`]). Areas that do not fit the readout or overlap
/// the visible area are skipped (a file's claim, not trusted); None when
/// a plane has fewer than [`MIN_PIXELS`]. Also gives the fewest pixels
/// of a plane.
pub fn measure(
    data: &[u16],
    size: (usize, usize),
    areas: &[Area],
    visible: (usize, usize, usize, usize),
    offsets: [(usize, usize); 4],
) -> Option<([f32; 4], usize)> {
    let (rows, cols) = size;
    let (y0, x0, h, w) = visible;
    let mut planes: [Vec<u16>; 4] = Default::default();
    for a in areas {
        let fits = a.top < a.bottom && a.left < a.right && a.bottom <= rows && a.right <= cols;
        let overlaps = a.top < y0 + h && y0 < a.bottom && a.left < x0 + w && x0 < a.right;
        if !fits || overlaps || data.len() != rows * cols {
            continue;
        }
        for r in a.top..a.bottom {
            for c in a.left..a.right {
                let cell = ((r + 2 - y0 % 2) % 2, (c + 2 - x0 % 2) % 2);
                let p = (0..4).find(|&p| offsets[p] == cell).unwrap_or(0);
                planes[p].push(data[r * cols + c]);
            }
        }
    }
    let fewest = planes.iter().map(Vec::len).min().unwrap_or(0);
    if fewest < MIN_PIXELS {
        return None;
    }
    let mut level = [0.0f32; 4];
    for (l, p) in level.iter_mut().zip(&planes) {
        *l = clipped_mean(p) as f32;
    }
    Some((level, fewest))
}

/// The mean of the values within 5 robust standard deviations (1.4826 x
/// the median absolute deviation, at least 1 DN) of their median
/// ([`pgrf_core::stats::median_and_robust_sd`]).
pub fn clipped_mean(v: &[u16]) -> f64 {
    let mut x: Vec<f64> = v.iter().map(|&x| x as f64).collect();
    let (med, sd) = pgrf_core::stats::median_and_robust_sd(&mut x);
    let reach = (5.0 * sd).max(1.0);
    let kept: Vec<f64> = x.into_iter().filter(|x| (x - med).abs() <= reach).collect();
    kept.iter().sum::<f64>() / kept.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Cfa;

    /// Seeded Gaussian read noise (sd 3 DN) around a known offset per plane,
    /// with hot pixels: the clipped mean finds each offset within 5
    /// standard errors (3 / sqrt(n)); a plain mean would be pulled up by
    /// the hot pixels by about 1 DN.
    #[test]
    fn the_clipped_mean_finds_each_planes_offset_past_hot_pixels() {
        let (rows, cols, strip) = (64, 80, 16);
        let offsets = [2048.0, 2049.5, 2047.25, 2050.0];
        let cfa = Cfa::Grbg;
        let mut s = 12345u64;
        let mut gauss = || {
            let mut u = || {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((s >> 11) as f64 + 0.5) / (1u64 << 53) as f64
            };
            (-2.0 * u().ln()).sqrt() * (std::f64::consts::TAU * u()).cos()
        };
        let visible = (0, strip, rows, cols - strip);
        let mut data = vec![0u16; rows * cols];
        for r in 0..rows {
            for c in 0..cols {
                // The visible area starts at column `strip` (even): its
                // phase holds across the strip.
                let p = cfa.plane_at(r, c);
                data[r * cols + c] = (offsets[p] + 3.0 * gauss()).round() as u16;
            }
        }
        for k in 0..20 {
            data[(3 * k) * cols + (k % strip)] = 4000;
        }
        let area = Area {
            top: 0,
            left: 0,
            bottom: rows,
            right: strip,
        };
        let (got, n) = measure(&data, (rows, cols), &[area], visible, cfa.offsets()).unwrap();
        assert_eq!(n, rows * strip / 4);
        let se = 3.0 / ((rows * strip / 4) as f64).sqrt();
        for p in 0..4 {
            assert!(
                (got[p] as f64 - offsets[p]).abs() < 5.0 * se,
                "plane {p}: {} vs {}",
                got[p],
                offsets[p]
            );
        }
        // An area over the visible pixels, or outside the readout, is not
        // measured; too few pixels give no measure.
        let over = Area {
            right: strip + 2,
            ..area
        };
        assert!(measure(&data, (rows, cols), &[over], visible, cfa.offsets()).is_none());
        let out = Area {
            bottom: rows + 1,
            ..area
        };
        assert!(measure(&data, (rows, cols), &[out], visible, cfa.offsets()).is_none());
        let small = Area { bottom: 8, ..area };
        assert!(measure(&data, (rows, cols), &[small], visible, cfa.offsets()).is_none());
    }
}
