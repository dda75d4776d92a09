//! A sensor's own signal-independent noise: a bank of residual frames (a
//! calibration's bias frames minus their mean, `pgrf calibrate`), drawn in
//! place of the parametric read, row and quantisation noise (the paper's
//! N_r, N_H and N_q), as "Noise modeling in one hour" (CVPR 2025) draws a
//! camera's noise from its dark frames: what a Gaussian or Tukey draw
//! misses (heavy tails, random telegraph pixels, row and column structure,
//! the ADC's own steps) comes with it.
//!
//! A capture takes, for each tile of the bank's size that it covers, one
//! bank frame and a shift of whole packed rows and columns (so sensor rows
//! stay rows and the CFA phase holds), both drawn from the capture's seed:
//! deterministic, whatever the thread count. A capture larger than the
//! bank repeats it with a fresh frame and shift per tile.

use crate::error::{NoiseError, Result};
use ndarray::Array3;
use pgrf_core::seed::{stream, Domain};
use rand::Rng;

/// Why `--noise-bank` is refused without a calibration: the one wording
/// `pgrf train` and `pgrf synth` give.
pub const NEEDS_CALIBRATION: &str =
    "--noise-bank draws from a calibration's bias frames: give --calib FILE";

/// Why `--noise-bank` is refused with another noise model than pgrf's;
/// `flag` is the command's flag that chooses the model.
pub fn needs_pgrf_model(flag: &str) -> String {
    format!(
        "--noise-bank replaces the pgrf model's read, row and quantisation noise: use {flag} pgrf"
    )
}

/// Most frames a calibration's bank holds: more adds little to a draw's
/// variety (each capture shifts its frame anew) and only grows the file.
pub const MAX_BANK_FRAMES: usize = 8;

/// The largest bank a calibration stores, bytes: frames are left out (and
/// large sensors' frames cropped to their centre) to stay within it.
pub const MAX_BANK_BYTES: usize = 32 << 20;

/// Residual noise frames of one sensor, packed `(4, H/2, W/2)` in DN (the
/// bias frames minus their mean, scaled to the variance of one frame).
#[derive(Clone, Debug)]
pub struct NoiseBank {
    frames: Vec<Array3<f32>>,
}

/// Which frame and shift a tile of a capture takes.
#[derive(Clone, Copy, Debug)]
struct TileDraw {
    frame: usize,
    dy: usize,
    dx: usize,
}

impl NoiseBank {
    /// A bank of `frames` ([`NoiseBank::check`]).
    pub fn new(frames: Vec<Array3<f32>>) -> Result<NoiseBank> {
        Self::check(&frames)?;
        Ok(NoiseBank { frames })
    }

    /// Refuse `frames` no bank can be drawn from: none, not all of one
    /// packed shape with four planes and pixels, or a value not finite.
    pub fn check(frames: &[Array3<f32>]) -> Result<()> {
        let Some(first) = frames.first() else {
            return Err(NoiseError::Bank(
                "a noise bank needs at least one frame".into(),
            ));
        };
        let dim = first.dim();
        if dim.0 != 4 || dim.1 == 0 || dim.2 == 0 {
            return Err(NoiseError::Bank(format!(
                "noise bank frames must be packed (4, H/2, W/2), got {:?}",
                first.shape()
            )));
        }
        if let Some(f) = frames.iter().find(|f| f.dim() != dim) {
            return Err(NoiseError::Bank(format!(
                "noise bank frames differ in shape: {:?} and {:?}",
                first.shape(),
                f.shape()
            )));
        }
        if frames.iter().flatten().any(|v| !v.is_finite()) {
            return Err(NoiseError::Bank("a noise bank value is not finite".into()));
        }
        Ok(())
    }

    /// The frames.
    pub fn frames(&self) -> &[Array3<f32>] {
        &self.frames
    }

    /// Packed rows and columns of each frame.
    pub fn dims(&self) -> (usize, usize) {
        let (_, h, w) = self.frames[0].dim();
        (h, w)
    }

    /// The bank's noise for packed row `i` of `plane` of a `(4, ph, pw)`
    /// capture of `seed`, written into `out` (`pw` values).
    pub(crate) fn row_into(&self, draw: &BankDraw, plane: usize, i: usize, out: &mut [f32]) {
        let (bh, bw) = self.dims();
        for (j, o) in out.iter_mut().enumerate() {
            let t = draw.tiles[(i / bh) * draw.cols + j / bw];
            let f = &self.frames[t.frame];
            *o = f[[plane, (i + t.dy) % bh, (j + t.dx) % bw]];
        }
    }

    /// What a capture of `seed` and packed size `(ph, pw)` draws: a frame
    /// and a shift per bank-sized tile, row-major.
    pub(crate) fn draw(&self, seed: u64, ph: usize, pw: usize) -> BankDraw {
        let (bh, bw) = self.dims();
        let (rows, cols) = (ph.div_ceil(bh), pw.div_ceil(bw));
        let tiles = (0..rows * cols)
            .map(|t| {
                let mut rng = stream(seed, Domain::Bank, t as u64, 0);
                TileDraw {
                    frame: rng.random_range(0..self.frames.len()),
                    dy: rng.random_range(0..bh),
                    dx: rng.random_range(0..bw),
                }
            })
            .collect();
        BankDraw { tiles, cols }
    }
}

/// A capture's frames and shifts, tile by tile ([`NoiseBank::draw`]).
pub(crate) struct BankDraw {
    tiles: Vec<TileDraw>,
    cols: usize,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bank() -> NoiseBank {
        let f = |k: f32| {
            Array3::from_shape_fn((4, 6, 8), |(p, i, j)| k + (p * 100 + i * 10 + j) as f32)
        };
        NoiseBank::new(vec![f(0.0), f(1000.0)]).unwrap()
    }

    /// A capture's rows are the bank's rows, shifted as a whole and wrapped:
    /// each output row is a cyclic shift of one bank row of its plane, and
    /// the same seed gives the same draw.
    #[test]
    fn rows_are_shifted_bank_rows() {
        let b = bank();
        let d = b.draw(7, 6, 8);
        let mut row = vec![0.0; 8];
        b.row_into(&d, 2, 3, &mut row);
        let base = row[0] - row[0] % 10.0;
        // Plane 2's values, one bank row, every column once.
        let mut cols: Vec<usize> = row.iter().map(|v| (v - base) as usize).collect();
        assert!(
            row.iter().all(|v| ((v % 1000.0) / 100.0).floor() == 2.0),
            "{row:?}"
        );
        cols.sort_unstable();
        assert_eq!(cols, (0..8).collect::<Vec<_>>());
        let mut again = vec![0.0; 8];
        b.row_into(&b.draw(7, 6, 8), 2, 3, &mut again);
        assert_eq!(row, again);
    }

    /// A capture twice the bank's size takes four tiles, drawn apart.
    #[test]
    fn larger_captures_tile_the_bank() {
        let b = bank();
        let d = b.draw(3, 12, 16);
        assert_eq!((d.tiles.len(), d.cols), (4, 2));
    }

    #[test]
    fn bad_banks_are_refused() {
        assert!(NoiseBank::new(vec![]).is_err());
        assert!(NoiseBank::new(vec![Array3::zeros((3, 2, 2))]).is_err());
        assert!(NoiseBank::new(vec![Array3::zeros((4, 2, 2)), Array3::zeros((4, 2, 4))]).is_err());
        assert!(NoiseBank::new(vec![Array3::from_elem((4, 2, 2), f32::NAN)]).is_err());
    }
}
