//! What a frame's samples are, plane by plane: the range, the mean and the
//! share at or above the white level (what `pgrf info` shows of a file).
//! A Bayer frame has four planes (R, G1, B, G2); a monochrome frame has one,
//! all of its pixels, since its 2x2 sub-lattices are one colour and one
//! signal that only packing for a denoiser splits.

use crate::error::Result;
use crate::frame::RawFrame;
use crate::pack::pack_u16;
use ndarray::Axis;
use serde::Serialize;

/// The samples of one plane.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PlaneStats {
    /// The plane's name (R, G1, B, G2; or [`MONO_PLANE`]).
    pub plane: &'static str,
    /// The plane's width in pixels (half the frame's for a Bayer plane).
    pub width: usize,
    /// The plane's height in pixels.
    pub height: usize,
    /// Smallest sample, DN.
    pub min: u16,
    /// Largest sample, DN.
    pub max: u16,
    /// Mean sample, DN.
    pub mean: f64,
    /// Share of samples at or above the white level.
    pub saturated: f64,
}

/// The name of a monochrome frame's one plane.
pub const MONO_PLANE: &str = "mono";

/// The statistics of `f`'s planes: a Bayer frame's four packed planes in
/// the packing's order (odd trailing rows and columns left out, as packing
/// does), a monochrome frame's one plane of every pixel.
pub fn plane_stats(f: &RawFrame) -> Result<Vec<PlaneStats>> {
    if f.mono {
        let view = ndarray::ArrayView2::from_shape((f.height, f.width), &f.mosaic[..])
            .expect("a frame holds width x height samples");
        return Ok(vec![one_plane(MONO_PLANE, view, f.white)]);
    }
    let p = pack_u16(f)?;
    Ok((0..4)
        .map(|c| one_plane(f.plane_names()[c], p.index_axis(Axis(0), c), f.white))
        .collect())
}

/// Range, mean and saturated share of the samples of `plane`.
fn one_plane(name: &'static str, plane: ndarray::ArrayView2<u16>, white: u32) -> PlaneStats {
    let n = plane.len() as f64;
    let (mut min, mut max, mut sum, mut sat) = (u16::MAX, 0u16, 0u64, 0usize);
    for &v in plane.iter() {
        min = min.min(v);
        max = max.max(v);
        sum += v as u64;
        sat += (v as u32 >= white) as usize;
    }
    PlaneStats {
        plane: name,
        width: plane.ncols(),
        height: plane.nrows(),
        min,
        max,
        mean: sum as f64 / n,
        saturated: sat as f64 / n,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cfa::Cfa;

    /// A 6x4 ramp (odd sizes would be cut by packing, not here): a
    /// monochrome frame is one plane of all 24 samples, a Bayer frame of
    /// the same samples four planes of 6 each.
    #[test]
    fn a_monochrome_frame_is_one_plane_and_a_bayer_frame_four() {
        let mosaic: Vec<u16> = (0..24).map(|v| v * 10).collect();
        let mono = RawFrame::from_mono(6, 4, mosaic.clone(), 0.0, 200).unwrap();
        let s = plane_stats(&mono).unwrap();
        assert_eq!(s.len(), 1);
        assert_eq!(
            (s[0].plane, s[0].width, s[0].height, s[0].min, s[0].max),
            (MONO_PLANE, 6, 4, 0, 230)
        );
        assert!((s[0].mean - 115.0).abs() < 1e-9, "{}", s[0].mean);
        // 200..=230: 4 of 24 at or above white.
        assert!((s[0].saturated - 4.0 / 24.0).abs() < 1e-12);
        let bayer = RawFrame::from_mosaic(6, 4, mosaic, Cfa::Rggb, [0.0; 4], 200).unwrap();
        let s = plane_stats(&bayer).unwrap();
        let names: Vec<_> = s.iter().map(|p| p.plane).collect();
        assert_eq!(names, ["R", "G1", "B", "G2"]);
        // R: rows 0 and 2, columns 0, 2, 4: 0,20,40,120,140,160 x 1.
        assert_eq!(
            (s[0].width, s[0].height, s[0].min, s[0].max),
            (3, 2, 0, 160)
        );
        assert!((s[0].mean - 80.0).abs() < 1e-9);
    }
}
