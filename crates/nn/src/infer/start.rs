//! The flow's start X0 ~ N(0, I) for a whole frame.
//!
//! Drawn once for the full packed image, from one generator per
//! (sample, plane, row) seeded by hashing, so that two overlapping tiles see
//! the same X0 at the same pixel (otherwise they would disagree by a fresh
//! sample's worth and the blend would show), and so that the same seed gives
//! the same image whatever the tiling and the thread count.

use ndarray::Array3;
use pgrf_core::seed::{stream, Domain};
use rayon::prelude::*;

/// Keeps start-noise streams apart from the noise model's.
const START_DOMAIN: u64 = 0x7830; // "x0"

/// The start X0 ~ N(0, I): a standard normal `(c, h, w)` field for sample
/// `k` under `seed`, row r of the flattened `(c * h)` rows drawn from its
/// own stream, so any window of it is the same whatever the tiling.
pub fn start_noise(seed: u64, k: u64, c: usize, h: usize, w: usize) -> Array3<f32> {
    let mut a = Array3::<f32>::zeros((c, h, w));
    if w == 0 {
        return a;
    }
    a.as_slice_mut()
        .expect("standard layout")
        .par_chunks_mut(w)
        .enumerate()
        .for_each(|(r, row)| {
            let mut rng = stream(
                seed ^ START_DOMAIN.rotate_left(40),
                Domain::Pixel,
                k,
                r as u64,
            );
            crate::flow::draw::fill_start(&mut rng, row);
        });
    a
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn start_noise_is_standard_normal_and_seeded() {
        let a = start_noise(7, 0, 4, 64, 64);
        let b = start_noise(7, 0, 4, 64, 64);
        let c = start_noise(7, 1, 4, 64, 64);
        assert_eq!(a, b);
        assert_ne!(a, c);
        let n = a.len() as f64;
        let mean = a.iter().map(|&v| v as f64).sum::<f64>() / n;
        let var = a.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / n;
        // 16384 draws: SE of the mean 0.0078, of the variance ~0.011; 5 SE.
        assert!(mean.abs() < 0.04, "mean {mean}");
        assert!((var - 1.0).abs() < 0.056, "var {var}");
    }
}
