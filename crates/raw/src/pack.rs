//! Bayer mosaic <-> 4-plane packed arrays (R, G1, B, G2), the representation
//! every network and noise model in pgrf works on.
//!
//! Shapes are channel-first, `(4, H/2, W/2)`, as the field's PyTorch code uses.
//! A trailing odd row or column belongs to no complete 2x2 cell: packing leaves
//! it out and unpacking keeps the template frame's values there, so a round trip
//! never invents or loses a pixel.

use crate::error::{RawError, Result};
use crate::frame::RawFrame;
use ndarray::{Array3, ArrayView3, Axis};
use rayon::prelude::*;

/// Pack the mosaic into 4 planes of raw DN (black not subtracted), shape
/// `(4, H/2, W/2)` in R, G1, B, G2 order; a trailing odd row or column is
/// left out.
pub fn pack_u16(frame: &RawFrame) -> Result<Array3<u16>> {
    pack_map(frame, |_, v| v)
}

/// Pack and normalise to `(x - black[c]) / (white - black[c])`: shape
/// `(4, H/2, W/2)` in R, G1, B, G2 order, the representation every network
/// and noise model in pgrf works on (a trailing odd row or column is left out).
///
/// With `clip` the result is clamped to [0, 1] (the ELD/SID convention for
/// network inputs and metrics); without it values below black stay negative,
/// which noise statistics need.
pub fn pack_normalized(frame: &RawFrame, clip: bool) -> Result<Array3<f32>> {
    let black = frame.black;
    let scale: [f32; 4] = std::array::from_fn(|p| 1.0 / (frame.white as f32 - black[p]));
    if clip {
        pack_map(frame, |p, v| {
            ((v as f32 - black[p]) * scale[p]).clamp(0.0, 1.0)
        })
    } else {
        pack_map(frame, |p, v| (v as f32 - black[p]) * scale[p])
    }
}

/// One pass over the mosaic: each pair of rows fills one row of all four
/// planes, so the mosaic is read once (a per-plane loop reads it four times;
/// measured 24 ms -> see BENCHMARKS.md for 12 MP).
fn pack_map<T: Copy + Default + Send + Sync>(
    frame: &RawFrame,
    f: impl Fn(usize, u16) -> T + Sync,
) -> Result<Array3<T>> {
    let (ph, pw) = packed_dims_checked(frame)?;
    let off = frame.cfa.offsets();
    let w = frame.width;
    let n = ph * pw;
    let mut data = vec![T::default(); 4 * n];
    {
        let (p0, rest) = data.split_at_mut(n);
        let (p1, rest) = rest.split_at_mut(n);
        let (p2, p3) = rest.split_at_mut(n);
        p0.par_chunks_mut(pw)
            .zip(p1.par_chunks_mut(pw))
            .zip(p2.par_chunks_mut(pw))
            .zip(p3.par_chunks_mut(pw))
            .enumerate()
            .for_each(|(i, (((r0, r1), r2), r3))| {
                let rows = &frame.mosaic[2 * i * w..(2 * i + 2) * w];
                for (plane, dst) in [r0, r1, r2, r3].into_iter().enumerate() {
                    let (dr, dc) = off[plane];
                    let src = &rows[dr * w + dc..];
                    for (j, d) in dst.iter_mut().enumerate() {
                        *d = f(plane, src[2 * j]);
                    }
                }
            });
    }
    Ok(Array3::from_shape_vec((4, ph, pw), data).expect("4 * ph * pw elements"))
}

/// Write 4 packed planes of DN back into a copy of `template`'s mosaic.
pub fn unpack_u16(packed: ArrayView3<u16>, template: &RawFrame) -> Result<RawFrame> {
    check_shape(packed.shape(), template)?;
    let off = template.cfa.offsets();
    let mut mosaic = template.mosaic.clone();
    let w = template.width;
    mosaic
        .par_chunks_mut(2 * w)
        .enumerate()
        .filter(|(_, pair)| pair.len() == 2 * w)
        .for_each(|(i, pair)| {
            for (plane, &(dr, dc)) in off.iter().enumerate() {
                let src = packed.index_axis(Axis(0), plane);
                let src = src.index_axis(Axis(0), i);
                let dst = &mut pair[dr * w..(dr + 1) * w];
                for (j, v) in src.iter().enumerate() {
                    dst[2 * j + dc] = *v;
                }
            }
        });
    template.with_mosaic(mosaic)
}

/// Inverse of [`pack_normalized`]: `x * (white - black[c]) + black[c]`,
/// rounded to the nearest DN and saturated to the u16 range. NaN is refused,
/// because writing it as 0 would be a silent wrong answer.
pub fn unpack_normalized(packed: ArrayView3<f32>, template: &RawFrame) -> Result<RawFrame> {
    check_shape(packed.shape(), template)?;
    if let Some(pos) = packed.iter().position(|v| v.is_nan()) {
        return Err(RawError::PackedNan { index: pos });
    }
    let mut dn = Array3::<u16>::zeros(packed.raw_dim());
    for plane in 0..4 {
        let black = template.black[plane];
        let range = template.white as f32 - black;
        let src = packed.index_axis(Axis(0), plane);
        let mut dst = dn.index_axis_mut(Axis(0), plane);
        ndarray::Zip::from(&mut dst)
            .and(&src)
            .par_for_each(|d, &x| *d = (x * range + black).round().clamp(0.0, 65535.0) as u16);
    }
    unpack_u16(dn.view(), template)
}

fn packed_dims_checked(frame: &RawFrame) -> Result<(usize, usize)> {
    let (ph, pw) = frame.packed_dims();
    if ph == 0 || pw == 0 {
        return Err(RawError::TooSmallToPack {
            width: frame.width,
            height: frame.height,
        });
    }
    if frame.mosaic.len() != frame.width * frame.height {
        return Err(RawError::MosaicInconsistent);
    }
    Ok((ph, pw))
}

fn check_shape(shape: &[usize], template: &RawFrame) -> Result<()> {
    let (ph, pw) = packed_dims_checked(template)?;
    if shape != [4, ph, pw] {
        return Err(RawError::PackedShape {
            shape: shape.to_vec(),
            width: template.width,
            height: template.height,
            packed_height: ph,
            packed_width: pw,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cfa::Cfa;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_frame(cfa: Cfa, w: usize, h: usize, seed: u64) -> RawFrame {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mosaic = (0..w * h).map(|_| rng.random::<u16>()).collect();
        RawFrame::from_mosaic(w, h, mosaic, cfa, [512.0, 510.0, 514.0, 508.0], 65535).unwrap()
    }

    #[test]
    fn pack_unpack_pack_is_lossless_for_every_phase() {
        for (k, cfa) in Cfa::ALL.into_iter().enumerate() {
            // Odd sizes exercise the trailing row/column that no cell covers.
            for (w, h) in [(16, 10), (17, 11), (2, 2)] {
                let f = random_frame(cfa, w, h, 100 + k as u64);
                let p = pack_u16(&f).unwrap();
                let back = unpack_u16(p.view(), &f).unwrap();
                assert_eq!(back.mosaic, f.mosaic, "{cfa} {w}x{h}");
                assert_eq!(pack_u16(&back).unwrap(), p);
            }
        }
    }

    #[test]
    fn unpack_writes_new_values_in_the_right_places() {
        for (k, cfa) in Cfa::ALL.into_iter().enumerate() {
            let f = random_frame(cfa, 12, 8, 7 + k as u64);
            let mut p = pack_u16(&f).unwrap();
            p.mapv_inplace(|v| v.wrapping_add(1));
            let back = unpack_u16(p.view(), &f).unwrap();
            for r in 0..8 {
                for c in 0..12 {
                    assert_eq!(back.at(r, c), f.at(r, c).wrapping_add(1));
                }
            }
        }
    }

    #[test]
    fn planes_hold_the_named_colours() {
        // A mosaic whose value encodes its colour: R=1, G=2, B=3.
        for cfa in Cfa::ALL {
            let (w, h) = (8, 6);
            let mosaic = (0..w * h)
                .map(|i| [1u16, 2, 3][cfa.color_at(i / w, i % w)])
                .collect();
            let f = RawFrame::from_mosaic(w, h, mosaic, cfa, [0.0; 4], 255).unwrap();
            let p = pack_u16(&f).unwrap();
            for (plane, want) in [1u16, 2, 3, 2].into_iter().enumerate() {
                assert!(
                    p.index_axis(Axis(0), plane).iter().all(|&v| v == want),
                    "{cfa} plane {plane}"
                );
            }
        }
    }

    #[test]
    fn normalisation_matches_hand_computed_values() {
        // RGGB 2x2: R=600, G1=1000, G2=15520, B=8060; black 600 (R,G1) 500 (B,G2), white 15520.
        let f = RawFrame::from_mosaic(
            2,
            2,
            vec![600, 1000, 15520, 8060],
            Cfa::Rggb,
            [600.0, 600.0, 500.0, 500.0],
            15520,
        )
        .unwrap();
        let p = pack_normalized(&f, true).unwrap();
        let got: Vec<f32> = p.iter().copied().collect();
        let want = [0.0, 400.0 / 14920.0, 7560.0 / 15020.0, 1.0];
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 1e-7, "{got:?} vs {want:?}");
        }
        // Below black: negative without clipping, 0 with.
        let dark =
            RawFrame::from_mosaic(2, 2, vec![100, 600, 600, 600], Cfa::Rggb, [600.0; 4], 15520)
                .unwrap();
        assert!((pack_normalized(&dark, false).unwrap()[[0, 0, 0]] + 500.0 / 14920.0).abs() < 1e-7);
        assert_eq!(pack_normalized(&dark, true).unwrap()[[0, 0, 0]], 0.0);
    }

    #[test]
    fn normalized_round_trip_is_exact_on_u16_data() {
        for (k, cfa) in Cfa::ALL.into_iter().enumerate() {
            let mut f = random_frame(cfa, 20, 14, 40 + k as u64);
            f.white = 16383;
            f.mosaic.iter_mut().for_each(|v| *v %= 16384);
            let p = pack_normalized(&f, false).unwrap();
            let back = unpack_normalized(p.view(), &f).unwrap();
            assert_eq!(back.mosaic, f.mosaic, "{cfa}");
        }
    }

    #[test]
    fn shape_mismatch_and_nan_are_refused() {
        let f = random_frame(Cfa::Rggb, 8, 8, 1);
        assert!(unpack_u16(Array3::<u16>::zeros((4, 3, 4)).view(), &f).is_err());
        let mut p = pack_normalized(&f, true).unwrap();
        p[[2, 1, 1]] = f32::NAN;
        let e = unpack_normalized(p.view(), &f).unwrap_err().to_string();
        assert!(e.contains("NaN"), "{e}");
    }
}
