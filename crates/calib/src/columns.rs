//! Defective columns: a column amplifier's offset or gain, found per
//! physical sensor column against its neighbours, on the rows where it is
//! defective.
//!
//! Each pixel of such a column is only a little off, far under a per-pixel
//! threshold, but the column stands out over a stretch of rows. Compared
//! with the whole plane it would not stand out alone: a CCD's bias ramp
//! (12 DN over a hundred columns) and a flat's vignetting or uneven lamp
//! move whole regions of columns more than a bad column differs from its
//! neighbours, and a per-plane count makes one physical column two (or,
//! on a monochrome sensor stored as four sub-lattices, flags it on
//! alternate rows). So the maps are unpacked to the sensor's rows and
//! columns (each plane normalised by its median first, so colours
//! compare), each pixel is compared with the median of its row's two
//! neighbours on each side (what is smooth over a few columns cancels),
//! and that deviation's running median down the column, over rows of one
//! colour, must stand out over a stretch: a whole column is flagged on
//! every row, a column bad from some row on (a CCD's charge trap) from
//! there, a colour of a column on its own rows.

use ndarray::Array3;
use pgrf_core::stats::{median, median_and_robust_sd};

/// Sensor rows of one parity on each side of a row that the running
/// median of a column's deviation takes: a stretch must be bad over about
/// 2 x 16 rows of a colour to be a column defect (a hot pixel or a cosmic
/// ray moves no median of 33), and a partial column is flagged from within
/// a few rows of where it starts.
const RUN_HALF: usize = 16;

/// How far (in robust standard deviations of every smoothed deviation of
/// the map) a stretch must lie from its neighbours: 5, so that among a
/// megapixel's well-behaved columns none is by chance.
const COLUMN_Z: f64 = 5.0;

/// The fewest rows of one parity a defective stretch spans ([`RUN_HALF`]):
/// shorter excursions are single pixels' business (hot, cold, dead).
const MIN_RUN: usize = RUN_HALF;

/// A packed response map (the flats' mean response per pixel) unpacked to
/// the sensor's rows and columns (`offsets`: each plane's row and column
/// offset in the 2 x 2 cell), every plane over its median minus 1 so that
/// colours compare: row-major, NaN where a value is not finite (or the
/// plane's median is not positive).
fn sensor_image(map: &Array3<f32>, offsets: [(usize, usize); 4]) -> Vec<f64> {
    let (_, ph, pw) = map.dim();
    let (h, w) = (2 * ph, 2 * pw);
    let mut img = vec![f64::NAN; h * w];
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
        let (dy, dx) = offsets[p];
        for ((i, j), &v) in plane.indexed_iter() {
            let v = v as f64;
            img[(2 * i + dy) * w + 2 * j + dx] = match v.is_finite() && m > 0.0 {
                true => v / m - 1.0,
                false => f64::NAN,
            };
        }
    }
    img
}

/// Each pixel's value minus what its row's neighbours of the same column
/// parity (the same colour plane on a Bayer sensor, which its own median
/// normalised) predict there: the median of the means of the pairs at
/// x - 2k and x + 2k (k = 1, 2, 3), in which a ramp or vignetting across
/// the pair cancels; where fewer than two such pairs are known (the
/// sensor's edges), also the lines through x + 2k and x + 4k (or x - 2k and
/// x - 4k, k = 1, 2, 3) extrapolated to x, so that one bad column among
/// them moves no median. Pixels in `skip` and non-finite
/// values predict nothing. What the pixel's column alone does there; NaN
/// where fewer than two predictions are known.
fn row_deviations(img: &[f64], w: usize, skip: &[bool]) -> Vec<f64> {
    let mut out = vec![f64::NAN; img.len()];
    let mut guess = Vec::with_capacity(7);
    for (y, row) in img.chunks(w).enumerate() {
        let skip = &skip[y * w..(y + 1) * w];
        let at = |j: isize| {
            (j >= 0 && (j as usize) < w)
                .then_some(j as usize)
                .filter(|&j| !skip[j] && row[j].is_finite())
                .map(|j| row[j])
        };
        for x in 0..w {
            let xi = x as isize;
            guess.clear();
            guess.extend(
                [2, 4, 6]
                    .into_iter()
                    .filter_map(|k| Some((at(xi - k)? + at(xi + k)?) / 2.0)),
            );
            if guess.len() < 2 {
                for (k, d) in [(2, 1), (4, 1), (6, 1), (2, -1), (4, -1), (6, -1)] {
                    if let (Some(a), Some(b)) = (at(xi + d * k), at(xi + 2 * d * k)) {
                        guess.push(2.0 * a - b);
                    }
                }
            }
            if row[x].is_finite() && guess.len() >= 2 {
                out[y * w + x] = row[x] - median(&mut guess);
            }
        }
    }
    out
}

/// The running median of `dev` down each column over rows of one parity
/// ([`RUN_HALF`] of them on each side, fewer at the top and bottom edges):
/// a defective stretch of a column stands out, a single pixel does not.
fn running_medians(dev: &[f64], w: usize) -> Vec<f64> {
    let h = dev.len() / w.max(1);
    let mut out = vec![f64::NAN; dev.len()];
    let mut win = Vec::with_capacity(2 * RUN_HALF + 1);
    for x in 0..w {
        for y in 0..h {
            let (q, k) = (y % 2, y / 2);
            let rows = h.saturating_sub(q).div_ceil(2);
            win.clear();
            win.extend(
                (k.saturating_sub(RUN_HALF)..(k + RUN_HALF + 1).min(rows))
                    .map(|kk| dev[(2 * kk + q) * w + x])
                    .filter(|v| v.is_finite()),
            );
            if win.len() > RUN_HALF {
                out[y * w + x] = median(&mut win);
            }
        }
    }
    out
}

/// The defective stretches of the sensor's columns in a packed map
/// (`offsets` as in [`sensor_image`]): every (row, column) of the sensor
/// whose column stands out from its row neighbours ([`row_deviations`])
/// over a stretch of at least [`MIN_RUN`] rows of its colour, judged by the
/// running median ([`running_medians`]) against [`COLUMN_Z`] robust
/// standard deviations (1.4826 MAD of every smoothed deviation of that row
/// parity, or the column's own noise where that is larger:
/// [`median_noise`]; floored at 1e-6). A whole bad column is flagged on all its rows,
/// a partial one on its stretch, a colour of a column on its rows only.
/// Twice: the second time the first's flags are left out of every
/// neighbourhood, so a bad column does not make its neighbours look bad
/// (at the sensor's edge, where one side has no neighbours) or hide a bad
/// neighbour. Returns the flags (row-major, the sensor's size) and the
/// columns with any, ascending.
pub(crate) fn defective_column_rows(
    map: &Array3<f32>,
    offsets: [(usize, usize); 4],
) -> (Vec<bool>, Vec<usize>) {
    let (_, ph, pw) = map.dim();
    let (h, w) = (2 * ph, 2 * pw);
    let img = sensor_image(map, offsets);
    let first = flag_stretches(&img, w, &vec![false; h * w]);
    let flags = flag_stretches(&img, w, &first);
    let columns = (0..w)
        .filter(|&x| (0..h).any(|y| flags[y * w + x]))
        .collect();
    (flags, columns)
}

/// The pixels of `img` (the sensor's, `w` wide) in defective column
/// stretches, neighbourhoods leaving out `skip` ([`defective_column_rows`]).
fn flag_stretches(img: &[f64], w: usize, skip: &[bool]) -> Vec<bool> {
    let h = img.len() / w.max(1);
    let dev = row_deviations(img, w, skip);
    let smooth = running_medians(&dev, w);
    let mut flags = vec![false; h * w];
    for q in 0..2 {
        let mut finite: Vec<f64> = (q..h)
            .step_by(2)
            .flat_map(|y| smooth[y * w..(y + 1) * w].iter().copied())
            .filter(|v| v.is_finite())
            .collect();
        if finite.is_empty() {
            continue;
        }
        let (m, sd) = median_and_robust_sd(&mut finite);
        for x in 0..w {
            let limit = COLUMN_Z * sd.max(median_noise(&dev, w, x, q)).max(1e-6);
            let out: Vec<bool> = (q..h)
                .step_by(2)
                .map(|y| (smooth[y * w + x] - m).abs() > limit)
                .collect();
            flag_runs(&out, |k| flags[(2 * k + q) * w + x] = true);
        }
    }
    flags
}

/// The standard deviation the running median of column `x`'s deviations
/// over rows of parity `q` has from their noise alone: 1.2533 x their
/// robust standard deviation / sqrt(2 [`RUN_HALF`] + 1) (the median of n
/// normal values). Near the sensor's edges, where predictions are
/// extrapolated, it is larger than in the middle, and the limit follows.
fn median_noise(dev: &[f64], w: usize, x: usize, q: usize) -> f64 {
    let h = dev.len() / w.max(1);
    let mut v: Vec<f64> = (q..h)
        .step_by(2)
        .map(|y| dev[y * w + x])
        .filter(|v| v.is_finite())
        .collect();
    if v.len() < 2 {
        return 0.0;
    }
    let (_, sd) = median_and_robust_sd(&mut v);
    1.2533 * sd / ((2 * RUN_HALF + 1) as f64).sqrt()
}

/// Call `flag` with each index of the runs of `out` at least [`MIN_RUN`]
/// long.
fn flag_runs(out: &[bool], mut flag: impl FnMut(usize)) {
    let mut start = None;
    for k in 0..=out.len() {
        match (start, out.get(k).copied().unwrap_or(false)) {
            (None, true) => start = Some(k),
            (Some(s), false) => {
                if k - s >= MIN_RUN {
                    (s..k).for_each(&mut flag);
                }
                start = None;
            }
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RGGB: [(usize, usize); 4] = [(0, 0), (0, 1), (1, 1), (1, 0)];

    /// A 4 x 64 x 64 packed response map (a 128 x 128 sensor) of 100: a
    /// ramp of 0.1 per column, a parabola of 5 across the sensor, uniform
    /// noise of +-0.5 (a fixed hash of the position: a stack's residual),
    /// and `bad(plane, sensor row, sensor column)` more.
    fn map(bad: impl Fn(usize, usize, usize) -> f32) -> Array3<f32> {
        Array3::from_shape_fn((4, 64, 64), |(p, i, j)| {
            let (y, x) = (2 * i + RGGB[p].0, 2 * j + RGGB[p].1);
            let xf = x as f32;
            // splitmix64's finaliser of the position.
            let mut h = (y * 128 + x) as u64 ^ 0x9E37_79B9_7F4A_7C15;
            h = (h ^ (h >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            h = (h ^ (h >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            let noise = ((h ^ (h >> 31)) >> 40) as f32 / (1u64 << 24) as f32 - 0.5;
            100.0 + 0.1 * xf + 5.0 * ((xf - 64.0) / 64.0).powi(2) + noise + bad(p, y, x)
        })
    }

    /// The sensor rows flagged in column `x`.
    fn rows_of(flags: &[bool], x: usize) -> Vec<usize> {
        (0..128).filter(|&y| flags[y * 128 + x]).collect()
    }

    /// Sensor column 9 (odd: planes G1 and B) 3 DN high is found once, on
    /// all 128 rows; high on its G1 rows only, on those 64 rows; nothing
    /// is found in the map without it.
    #[test]
    fn a_bad_column_among_ramps_is_found_on_its_rows() {
        let (flags, cols) = defective_column_rows(
            &map(|p, _, x| if x == 9 && p != 0 { 3.0 } else { 0.0 }),
            RGGB,
        );
        assert_eq!(cols, vec![9]);
        assert_eq!(rows_of(&flags, 9), (0..128).collect::<Vec<_>>());
        let (flags, cols) = defective_column_rows(
            &map(|p, _, x| if x == 9 && p == 1 { 3.0 } else { 0.0 }),
            RGGB,
        );
        assert_eq!(cols, vec![9]);
        assert_eq!(rows_of(&flags, 9), (0..128).step_by(2).collect::<Vec<_>>());
        let (flags, cols) = defective_column_rows(&map(|_, _, _| 0.0), RGGB);
        assert!(cols.is_empty() && !flags.contains(&true));
    }

    /// A column bad from sensor row 80 on (a charge trap) is flagged from
    /// within 4 rows of there and nowhere above; the edge columns 0 and
    /// 127, bad on every row, are found with their one-sided neighbours.
    #[test]
    fn partial_and_edge_columns_are_flagged_where_they_are_bad() {
        let bad = |_: usize, y: usize, x: usize| match (x, y) {
            (40, 80..) => 4.0,
            (0, _) | (127, _) => -4.0,
            _ => 0.0,
        };
        let (flags, cols) = defective_column_rows(&map(bad), RGGB);
        assert_eq!(cols, vec![0, 40, 127]);
        let rows = rows_of(&flags, 40);
        assert!(
            (76..=84).contains(&rows[0]) && rows.last() == Some(&127),
            "{rows:?}"
        );
        assert_eq!(rows.len(), 128 - rows[0]);
        assert_eq!(rows_of(&flags, 0).len(), 128);
        assert_eq!(rows_of(&flags, 127).len(), 128);
    }

    /// Runs shorter than [`MIN_RUN`] are not flagged.
    #[test]
    fn short_runs_are_left_to_the_pixel_tests() {
        let mut hit = Vec::new();
        let mut out = vec![false; 40];
        out[2..2 + MIN_RUN - 1].iter_mut().for_each(|v| *v = true);
        out[24..40].iter_mut().for_each(|v| *v = true);
        flag_runs(&out, |k| hit.push(k));
        assert_eq!(hit, (24..40).collect::<Vec<_>>());
    }
}
