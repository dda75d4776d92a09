//! A clean crop as every source hands it out: packed, normalised planes
//! and where they lie on the sensor (for per-pixel calibration maps and
//! row-noise parity). Its own module so that the sources (RAW folders,
//! photos, procedural scenes) share it without importing each other.

use pgrf_raw::ndarray::Array3;

/// A clean crop and its place on the sensor.
#[derive(Clone, Debug)]
pub(crate) struct Crop {
    /// Packed planes R, G1, B, G2, normalised (not clipped).
    pub(crate) clean: Array3<f32>,
    /// Sensor-row parity of each plane (from the CFA).
    pub(crate) plane_rows: [usize; 4],
    /// Top-left corner in packed coordinates of the source image.
    pub(crate) origin: (usize, usize),
    /// Packed size of the whole source image.
    pub(crate) image: (usize, usize),
}
