//! EXIF orientation applied to rendered previews. Raw pixels stay in sensor
//! order (the CFA phase depends on it); only pictures meant for eyes are
//! turned upright.

/// Apply EXIF orientation `code` (1..=8) to an interleaved image with `ch`
/// channels; returns the new buffer and its (width, height). Unknown codes
/// are treated as 1.
pub(crate) fn apply_orientation<T: Copy + Default>(
    data: &[T],
    width: usize,
    height: usize,
    ch: usize,
    code: u16,
) -> (Vec<T>, usize, usize) {
    assert_eq!(data.len(), width * height * ch);
    let (w, h) = (width, height);
    let swap = matches!(code, 5..=8);
    let (ow, oh) = if swap { (h, w) } else { (w, h) };
    // Source (x, y) for output (x', y').
    let src = |xo: usize, yo: usize| -> (usize, usize) {
        match code {
            2 => (w - 1 - xo, yo),
            3 => (w - 1 - xo, h - 1 - yo),
            4 => (xo, h - 1 - yo),
            5 => (yo, xo),
            6 => (yo, h - 1 - xo),
            7 => (w - 1 - yo, h - 1 - xo),
            8 => (w - 1 - yo, xo),
            _ => (xo, yo),
        }
    };
    let mut out = vec![T::default(); data.len()];
    for yo in 0..oh {
        for xo in 0..ow {
            let (x, y) = src(xo, yo);
            let s = (y * w + x) * ch;
            let d = (yo * ow + xo) * ch;
            out[d..d + ch].copy_from_slice(&data[s..s + ch]);
        }
    }
    (out, ow, oh)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Stored 3x2 image, pixel value = 10*row + col:
    ///   0  1  2
    ///  10 11 12
    fn stored() -> Vec<u8> {
        vec![0, 1, 2, 10, 11, 12]
    }

    #[test]
    fn all_eight_orientations() {
        let cases: [(u16, usize, usize, Vec<u8>); 8] = [
            (1, 3, 2, vec![0, 1, 2, 10, 11, 12]),
            (2, 3, 2, vec![2, 1, 0, 12, 11, 10]),
            (3, 3, 2, vec![12, 11, 10, 2, 1, 0]),
            (4, 3, 2, vec![10, 11, 12, 0, 1, 2]),
            (5, 2, 3, vec![0, 10, 1, 11, 2, 12]),
            // 90 degrees clockwise: the stored left column becomes the top row.
            (6, 2, 3, vec![10, 0, 11, 1, 12, 2]),
            (7, 2, 3, vec![12, 2, 11, 1, 10, 0]),
            // 90 degrees counter-clockwise: the stored right column becomes the top row.
            (8, 2, 3, vec![2, 12, 1, 11, 0, 10]),
        ];
        for (code, w, h, want) in cases {
            let (got, ow, oh) = apply_orientation(&stored(), 3, 2, 1, code);
            assert_eq!((ow, oh, got), (w, h, want), "orientation {code}");
        }
    }

    #[test]
    fn rotations_compose() {
        // 6 (90 cw) applied twice equals 3 (180).
        let img: Vec<u8> = (0..12).collect();
        let (a, w, h) = apply_orientation(&img, 4, 3, 1, 6);
        let (b, _, _) = apply_orientation(&a, w, h, 1, 6);
        let (c, _, _) = apply_orientation(&img, 4, 3, 1, 3);
        assert_eq!(b, c);
    }
}
