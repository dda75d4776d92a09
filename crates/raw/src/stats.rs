//! What a frame's samples are, plane by plane: the range, the mean and the
//! share at or above the white level (what `pgrf info` shows of a file).

use crate::error::Result;
use crate::frame::RawFrame;
use crate::pack::pack_u16;
use ndarray::Axis;
use serde::Serialize;

/// The samples of one packed plane.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PlaneStats {
    /// The plane's name (R, G1, B, G2; or the monochrome sub-lattices').
    pub plane: &'static str,
    /// Smallest sample, DN.
    pub min: u16,
    /// Largest sample, DN.
    pub max: u16,
    /// Mean sample, DN.
    pub mean: f64,
    /// Share of samples at or above the white level.
    pub saturated: f64,
}

/// The statistics of `f`'s four packed planes, in the packing's order.
pub fn plane_stats(f: &RawFrame) -> Result<Vec<PlaneStats>> {
    let p = pack_u16(f)?;
    Ok((0..4)
        .map(|c| {
            let plane = p.index_axis(Axis(0), c);
            let n = plane.len() as f64;
            let (mut min, mut max, mut sum, mut sat) = (u16::MAX, 0u16, 0u64, 0usize);
            for &v in plane.iter() {
                min = min.min(v);
                max = max.max(v);
                sum += v as u64;
                sat += (v as u32 >= f.white) as usize;
            }
            PlaneStats {
                plane: f.plane_names()[c],
                min,
                max,
                mean: sum as f64 / n,
                saturated: sat as f64 / n,
            }
        })
        .collect())
}
