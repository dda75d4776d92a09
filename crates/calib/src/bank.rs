//! The calibration's noise bank ([`pgrf_noise::bank`]): the bias frames'
//! residual noise (each frame minus the master bias), stored with the maps
//! so that `pgrf synth --calib FILE --noise-bank` draws a capture's read,
//! row and quantisation noise from the sensor's own frames.

use crate::stack::Stack;
use ndarray::{s, Array3, ArrayView3};
use pgrf_noise::bank::{MAX_BANK_BYTES, MAX_BANK_FRAMES};

/// Largest side, in packed pixels, of a bank frame: a larger sensor's
/// frames are cropped to their centre (2048 x 2048 photosites, 16 MiB a
/// frame), so that at least two frames fit in [`MAX_BANK_BYTES`].
pub const MAX_BANK_SIDE: usize = 1024;

/// The centre [`MAX_BANK_SIDE`] crop of a packed frame `(4, ph, pw)`:
/// first row and column, rows, columns.
fn centre(ph: usize, pw: usize) -> (usize, usize, usize, usize) {
    let (h, w) = (ph.min(MAX_BANK_SIDE), pw.min(MAX_BANK_SIDE));
    ((ph - h) / 2, (pw - w) / 2, h, w)
}

/// The part of a bias frame (packed, DN) its bank frame is made of: kept
/// by the stack reader for the first [`MAX_BANK_FRAMES`] frames as it
/// decodes them, so that the bank needs no second decode.
pub(crate) fn bank_crop(packed: ArrayView3<u16>) -> Array3<u16> {
    let (_, ph, pw) = packed.dim();
    let (y0, x0, h, w) = centre(ph, pw);
    packed.slice(s![.., y0..y0 + h, x0..x0 + w]).to_owned()
}

/// The noise bank of the bias stack `bias` (read with its crops,
/// `ReadOptions::with_bank`; n frames of one exposure) whose per-pixel mean
/// (DN, packed) is `mean`, from its first frames' [`bank_crop`]s (in the
/// order read): as many as [`MAX_BANK_FRAMES`] and [`MAX_BANK_BYTES`]
/// allow, each taken minus the mean, times sqrt(n / (n - 1)) (a frame is in
/// the mean of n it is taken from, which would leave its residual that much
/// too quiet). None with fewer than two frames (one frame's residual is
/// zero).
pub(crate) fn bank_of(bias: &Stack, mean: &Array3<f64>) -> Vec<Array3<f32>> {
    let (crops, n) = (&bias.bank_crops, bias.groups[0].files.len());
    if n < 2 {
        return Vec::new();
    }
    let (_, ph, pw) = mean.dim();
    let (y0, x0, h, w) = centre(ph, pw);
    let frame_bytes = 4 * h * w * std::mem::size_of::<f32>();
    let count = crops
        .len()
        .min(n)
        .min(MAX_BANK_FRAMES)
        .min(MAX_BANK_BYTES / frame_bytes);
    let scale = (n as f64 / (n - 1) as f64).sqrt();
    let mean = mean.slice(s![.., y0..y0 + h, x0..x0 + w]);
    crops[..count]
        .iter()
        .map(|crop| {
            ndarray::Zip::from(crop)
                .and(&mean)
                .map_collect(|&v, &m| ((v as f64 - m) * scale) as f32)
        })
        .collect()
}
