//! The calibration's noise bank ([`pgrf_noise::bank`]): the bias frames'
//! residual noise (each frame minus the master bias), stored with the maps
//! so that `pgrf synth --calib FILE --noise-bank` draws a capture's read,
//! row and quantisation noise from the sensor's own frames.

use crate::error::{CalibError, Result};
use ndarray::{s, Array3};
use pgrf_noise::bank::{MAX_BANK_BYTES, MAX_BANK_FRAMES};
use pgrf_raw::{decode_file, pack_u16, LevelOverrides};
use std::path::PathBuf;

/// Largest side, in packed pixels, of a bank frame: a larger sensor's
/// frames are cropped to their centre (2048 x 2048 photosites, 16 MiB a
/// frame), so that at least two frames fit in [`MAX_BANK_BYTES`].
pub const MAX_BANK_SIDE: usize = 1024;

/// The noise bank of the bias frames `files` (all of one stack, in the
/// order read) whose per-pixel mean (DN, packed) is `mean`: the first
/// frames, as many as [`MAX_BANK_FRAMES`] and [`MAX_BANK_BYTES`] allow,
/// each cropped to its centre [`MAX_BANK_SIDE`] and taken minus the mean,
/// times sqrt(n / (n - 1)) (a frame is in the mean of n it is taken from,
/// which would leave its residual that much too quiet). None with fewer
/// than two frames (one frame's residual is zero).
pub(crate) fn bank_of(files: &[PathBuf], mean: &Array3<f64>) -> Result<Vec<Array3<f32>>> {
    let n = files.len();
    if n < 2 {
        return Ok(Vec::new());
    }
    let (_, ph, pw) = mean.dim();
    let (h, w) = (ph.min(MAX_BANK_SIDE), pw.min(MAX_BANK_SIDE));
    let (y0, x0) = ((ph - h) / 2, (pw - w) / 2);
    let frame_bytes = 4 * h * w * std::mem::size_of::<f32>();
    let count = n.min(MAX_BANK_FRAMES).min(MAX_BANK_BYTES / frame_bytes);
    let scale = (n as f64 / (n - 1) as f64).sqrt();
    let mean = mean.slice(s![.., y0..y0 + h, x0..x0 + w]);
    files[..count]
        .iter()
        .map(|f| {
            let frame = decode_file(f, &LevelOverrides::default())?;
            let packed = pack_u16(&frame)?;
            if packed.dim() != (4, ph, pw) {
                return Err(CalibError::MismatchedFrame {
                    file: f.clone(),
                    stack: "bias".into(),
                    what: crate::error::FrameField::Size,
                    expected: format!("{}x{} (when the stack was read)", 2 * pw, 2 * ph),
                    found: format!("{}x{}", frame.width, frame.height),
                });
            }
            let crop = packed.slice(s![.., y0..y0 + h, x0..x0 + w]);
            Ok(ndarray::Zip::from(&crop)
                .and(&mean)
                .map_collect(|&v, &m| ((v as f64 - m) * scale) as f32))
        })
        .collect()
}
