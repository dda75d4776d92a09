//! Apple's QuickTake files: no TIFF structure, only a header whose
//! dimensions rawler allocates before it decodes. They are bounded here by
//! [`MAX_PIXELS`](super::MAX_PIXELS) and by the pixel data the file holds.

use super::limits::too_many_pixels;
use super::order::Order;
use super::ContainerError;

/// The most pixels one byte of QuickTake pixel data can describe: the
/// QuickTake 100's codes take 3 bits per pixel, and the densest of RADC's
/// (150 and 200), a run of 8 steps of 4 pixels, at least 5 bits for 32
/// pixels (rawler's decompressors/radc.rs).
const QTK_PIXELS_PER_BYTE: u64 = 64;

/// An Apple QuickTake file ("qktk": QuickTake 100; "qktn": 150 and 200).
/// rawler's decoder (decoders/qtk.rs, `raw_image`, lines 79-103) reads the
/// height and width, big-endian, at byte 544, swaps them so that the width
/// is the larger, and allocates that image before it decodes the pixel
/// data, from byte 736 (738 when the 16-bit value at 552 is 30) to the end
/// of the file. Both the size and the data that could describe it bound the
/// dimensions.
pub(super) fn check_qtk(bytes: &[u8]) -> Result<(), ContainerError> {
    let be = Order(false);
    // rawler reads those 16 bytes first, and stops if they are not there.
    let (Some(h), Some(w), Some(hint)) =
        (be.u16(bytes, 544), be.u16(bytes, 546), be.u16(bytes, 552))
    else {
        return Ok(());
    };
    if bytes.len() < 560 {
        return Ok(());
    }
    let (w, h) = (w.max(h) as u64, w.min(h) as u64);
    if let Some(what) = too_many_pixels(w, h) {
        return Err(ContainerError::damaged(format!(
            "the QuickTake header claims {what}: it is damaged"
        )));
    }
    let data = (bytes.len() as u64).saturating_sub(if hint == 30 { 738 } else { 736 });
    if w * h > data * QTK_PIXELS_PER_BYTE {
        return Err(ContainerError::damaged(format!(
            "the QuickTake header claims a {w} x {h} image, but the file holds only {data} bytes of pixel data (at least 1 per {QTK_PIXELS_PER_BYTE} pixels): it is truncated or damaged"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::container::check;

    /// A QuickTake 150 file of `h` x `w` (as stored) with `data` bytes of
    /// pixel data after byte 736 (738 if `hint` is 30).
    fn qtk(h: u16, w: u16, hint: u16, data: usize) -> Vec<u8> {
        let mut b = b"qktn\0\0".to_vec();
        b.resize(544, 0);
        b.extend_from_slice(&h.to_be_bytes());
        b.extend_from_slice(&w.to_be_bytes());
        b.extend_from_slice(&[0; 4]);
        b.extend_from_slice(&hint.to_be_bytes());
        b.resize(736 + data, 0x5a);
        b
    }

    #[test]
    fn quicktake_dimensions_are_bounded_by_the_file() {
        // 640 x 480 needs 4800 bytes at 64 pixels a byte.
        assert_eq!(check(&qtk(480, 640, 0, 4800)), Ok(()));
        assert_eq!(check(&qtk(640, 480, 0, 4800)), Ok(()));
        let e = check(&qtk(480, 640, 0, 4799)).unwrap_err().to_string();
        assert!(
            e.contains("640 x 480 image") && e.contains("only 4799 bytes"),
            "{e}"
        );
        // With hint 30 the data starts 2 bytes later.
        assert!(check(&qtk(480, 640, 30, 4800)).is_err());
        let e = check(&qtk(43064, 60726, 0, 1)).unwrap_err().to_string();
        assert!(e.contains("60726 x 43064 image (2615 megapixels)"), "{e}");
        // Too short for the header rawler reads: it refuses it itself.
        assert_eq!(check(&qtk(480, 640, 0, 0)[..550]), Ok(()));
    }
}
