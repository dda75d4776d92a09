//! Defective columns: a column amplifier's offset or gain, found per
//! physical sensor column against its neighbours.
//!
//! Each pixel of such a column is only a little off, far under a per-pixel
//! threshold, but the column's median over its rows stands out. Compared
//! with the whole plane it would not stand out alone: a CCD's bias ramp
//! (12 DN over a hundred columns) and a flat's vignetting or uneven lamp
//! move whole regions of columns more than a bad column differs from its
//! neighbours, and a per-plane count makes one physical column two (or,
//! on a monochrome sensor stored as four sub-lattices, flags it on
//! alternate rows). So the maps are unpacked to the sensor's columns (each
//! plane normalised by its median first, so colours compare), each column's
//! median over its even rows and over its odd rows is taken (one plane
//! each), and each of the two profiles is compared with a straight line
//! fitted robustly through the column's neighbours: what is smooth over a
//! few columns (ramps, gradients, vignetting) is in the line, what one
//! column alone does is not. A column that stands out on either parity is
//! one defective column, all its rows flagged.

use ndarray::Array3;
use pgrf_core::stats::{median, median_and_robust_sd};

/// Neighbours on each side a column is compared with: the local line
/// spans 2 x 8 columns, over which a ramp or vignetting is straight, and
/// its robust fit ignores a few bad columns among them.
const HALF_WINDOW: usize = 8;

/// How far (in robust standard deviations of all columns' residuals) a
/// column must lie from its neighbours' line to be defective: 5, so that
/// among thousands of well-behaved columns none is by chance.
const COLUMN_Z: f64 = 5.0;

/// What a map's values mean, for putting the colour planes on one scale.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Scale {
    /// An offset in DN: each plane minus its median.
    Offset,
    /// A response to light: each plane over its median, minus 1.
    Response,
}

/// The median of each physical sensor column of a packed map over its even
/// rows and over its odd rows (`offsets`: each plane's row and column
/// offset in the 2 x 2 cell, so each half-column is one plane), every plane
/// normalised by its median as `scale` says: two profiles, by row parity.
/// NaN where a half-column has no finite value.
fn column_profiles(map: &Array3<f32>, offsets: [(usize, usize); 4], scale: Scale) -> [Vec<f64>; 2] {
    let (_, _, pw) = map.dim();
    let mut profiles = [vec![f64::NAN; 2 * pw], vec![f64::NAN; 2 * pw]];
    for (p, plane) in map.outer_iter().enumerate().take(4) {
        let mut finite: Vec<f64> = plane
            .iter()
            .filter(|v| v.is_finite())
            .map(|&v| v as f64)
            .collect();
        if finite.is_empty() {
            continue;
        }
        let m = median(&mut finite);
        let normalised = |v: f64| match scale {
            Scale::Offset => Some(v - m),
            Scale::Response => (m > 0.0).then(|| v / m - 1.0),
        };
        let (dy, dx) = offsets[p];
        for (j, column) in plane.columns().into_iter().enumerate() {
            let mut c: Vec<f64> = column
                .iter()
                .filter(|v| v.is_finite())
                .filter_map(|&v| normalised(v as f64))
                .collect();
            if !c.is_empty() {
                profiles[dy][2 * j + dx] = median(&mut c);
            }
        }
    }
    profiles
}

/// Each column's profile value minus what its neighbours predict there:
/// a Theil-Sen line (the median of the pairwise slopes, then the median
/// intercept) through the [`HALF_WINDOW`] columns on each side (shifted
/// inward at the sensor's edges, so an edge column is extrapolated to, not
/// compared with a lopsided median). NaN where too few neighbours are known.
fn local_residuals(profile: &[f64]) -> Vec<f64> {
    let w = profile.len();
    (0..w)
        .map(|x| {
            if !profile[x].is_finite() {
                return f64::NAN;
            }
            let span = (2 * HALF_WINDOW).min(w.saturating_sub(1));
            let start = x.saturating_sub(HALF_WINDOW).min(w - 1 - span);
            let near: Vec<(f64, f64)> = (start..=start + span)
                .filter(|&j| j != x && profile[j].is_finite())
                .map(|j| (j as f64 - x as f64, profile[j]))
                .collect();
            if near.len() < 2 {
                return f64::NAN;
            }
            let mut slopes = Vec::with_capacity(near.len() * (near.len() - 1) / 2);
            for (a, &(ja, ya)) in near.iter().enumerate() {
                for &(jb, yb) in &near[a + 1..] {
                    slopes.push((yb - ya) / (jb - ja));
                }
            }
            let slope = median(&mut slopes);
            let mut at_x: Vec<f64> = near.iter().map(|(j, y)| y - slope * j).collect();
            profile[x] - median(&mut at_x)
        })
        .collect()
}

/// The physical sensor columns of a packed map (`offsets` as in
/// [`column_profiles`]) whose median over their even or over their odd rows
/// lies more than [`COLUMN_Z`] robust standard deviations (1.4826 MAD of
/// all columns' residuals of that parity, floored at 1e-6) from the line
/// through their neighbours ([`local_residuals`]): sensor column indices,
/// ascending, each once, whether it stands out on all its rows or on
/// alternate ones.
pub(crate) fn defective_columns(
    map: &Array3<f32>,
    offsets: [(usize, usize); 4],
    scale: Scale,
) -> Vec<usize> {
    let mut out = Vec::new();
    for profile in column_profiles(map, offsets, scale) {
        let r = local_residuals(&profile);
        let mut finite: Vec<f64> = r.iter().copied().filter(|v| v.is_finite()).collect();
        if finite.is_empty() {
            continue;
        }
        let (m, sd) = median_and_robust_sd(&mut finite);
        let sd = sd.max(1e-6);
        out.extend(
            r.iter()
                .enumerate()
                .filter(|(_, v)| ((*v - m) / sd).abs() > COLUMN_Z)
                .map(|(x, _)| x),
        );
    }
    out.sort_unstable();
    out.dedup();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const RGGB: [(usize, usize); 4] = [(0, 0), (0, 1), (1, 1), (1, 0)];

    /// A 4 x 64 x 64 packed offset map (a 128-column sensor): a ramp of
    /// 0.1 DN per column, a parabola of 5 DN across the sensor, a
    /// deterministic +-0.5 DN pattern, and sensor column 9 (odd: planes G1
    /// and B) 3 DN high. Only column 9 is found, once; with the column
    /// instead 3 DN high on its G1 rows only (alternate rows), it is one
    /// column still.
    #[test]
    fn one_bad_column_among_ramps_is_found_once() {
        let map_with = |planes: &[usize]| {
            Array3::from_shape_fn((4, 64, 64), |(p, i, j)| {
                let x = (2 * j + RGGB[p].1) as f32;
                let mut v = 0.1 * x + 5.0 * ((x - 64.0) / 64.0).powi(2);
                v += 0.5 * (((p * 131 + i * 17 + j * 29) % 7) as f32 / 3.0 - 1.0);
                if x == 9.0 && planes.contains(&p) {
                    v += 3.0;
                }
                v
            })
        };
        assert_eq!(
            defective_columns(&map_with(&[1, 2]), RGGB, Scale::Offset),
            vec![9]
        );
        assert_eq!(
            defective_columns(&map_with(&[1]), RGGB, Scale::Offset),
            vec![9]
        );
        assert!(defective_columns(&map_with(&[]), RGGB, Scale::Offset).is_empty());
    }

    /// Edge columns are extrapolated to along the ramp, not compared with
    /// a one-sided median: a steep ramp flags nothing at the edges.
    #[test]
    fn edges_follow_the_ramp() {
        let profile: Vec<f64> = (0..40).map(|x| 3.0 * x as f64).collect();
        let r = local_residuals(&profile);
        assert!(r.iter().all(|v| v.abs() < 1e-9), "{r:?}");
    }
}
