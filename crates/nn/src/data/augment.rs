//! Flips and transposes of packed crops (ELD/SID's augmentation), drawn per
//! sample. Applied to packed planes as ELD does: the half-pixel shift between
//! Bayer sites that a packed flip implies is below what the network resolves.

use pgrf_raw::ndarray::{Array3, ArrayView3, Axis};
use rand::Rng;

/// One of the eight symmetries of the square, as the flips applied first
/// and the transpose applied last.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Augment {
    /// Flip top to bottom.
    pub(crate) flip_v: bool,
    /// Flip left to right.
    pub(crate) flip_h: bool,
    /// Swap rows and columns.
    pub(crate) transpose: bool,
}

impl Augment {
    /// No change.
    pub(crate) const IDENTITY: Augment = Augment {
        flip_v: false,
        flip_h: false,
        transpose: false,
    };

    /// Each of the eight symmetries of the square with probability 1/8.
    pub(crate) fn draw<R: Rng + ?Sized>(rng: &mut R) -> Augment {
        let b = rng.random::<u8>();
        Augment {
            flip_v: b & 1 != 0,
            flip_h: b & 2 != 0,
            transpose: b & 4 != 0,
        }
    }

    /// The augmented copy of a `(4, H, W)` array, in standard layout.
    pub(crate) fn apply(self, a: ArrayView3<f32>) -> Array3<f32> {
        let mut v = a;
        if self.flip_v {
            v.invert_axis(Axis(1));
        }
        if self.flip_h {
            v.invert_axis(Axis(2));
        }
        if self.transpose {
            v.swap_axes(1, 2);
        }
        v.as_standard_layout().into_owned()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn symmetries_move_pixels_where_they_should() {
        let a = Array3::from_shape_fn((4, 3, 5), |(p, i, j)| (p * 100 + i * 10 + j) as f32);
        let all = Augment {
            flip_v: true,
            flip_h: true,
            transpose: true,
        };
        let b = all.apply(a.view());
        assert_eq!(b.shape(), &[4, 5, 3]);
        // out[p, j, i] = in[p, 2 - i, 4 - j]
        assert_eq!(b[[1, 0, 0]], a[[1, 2, 4]]);
        assert_eq!(b[[2, 4, 1]], a[[2, 1, 0]]);
        assert_eq!(Augment::IDENTITY.apply(a.view()), a);
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(1);
        let mut seen = std::collections::HashSet::new();
        for _ in 0..200 {
            let d = Augment::draw(&mut rng);
            seen.insert((d.flip_v, d.flip_h, d.transpose));
        }
        assert_eq!(seen.len(), 8);
    }
}
