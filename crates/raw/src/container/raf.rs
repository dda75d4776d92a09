//! Fujifilm's RAF container: its own header, which points at the two TIFF
//! structures rawler parses. Only the pointers are RAF's; the structures
//! are walked by `tiff` (with Fujifilm's extra sub-IFD tag) and their
//! MakerNote by `makernote`.

use super::makernote::Notes;
use super::order::Order;
use super::tiff::check_tiff;
use super::ContainerError;

/// A RAF's TIFF structures also reach IFDs through Fujifilm's tag 0xF000.
const RAF_SUB_IFD_TAGS: [u16; 5] = [330, 34665, 34853, 40965, 0xF000];

/// A RAF's header holds, big-endian, the offset of the preview JPEG at byte
/// 84 (its EXIF TIFF starts 12 bytes into it) and the offset of the raw
/// IFDs at byte 100; rawler parses both as TIFF (offsets relative to their
/// start), so each is walked as a TIFF file of its own. A pointer past the
/// end, or to something that is not TIFF, is left to rawler, which refuses
/// the first and does not parse the second. The RAF decoder parses the
/// MakerNote it finds with `IFD::parse_makernote` (decoders/raf.rs, line
/// 243), offsets counting from the TIFF structure's header.
pub(super) fn check_raf(bytes: &[u8]) -> Result<(), ContainerError> {
    let be = Order(false);
    for (pointer, skip) in [(84, 12), (100, 0)] {
        let Some(offset) = be.u32(bytes, pointer) else {
            continue;
        };
        let start = offset as u64 + skip;
        let Some(tiff) = usize::try_from(start).ok().and_then(|s| bytes.get(s..)) else {
            continue;
        };
        check_tiff(tiff, &RAF_SUB_IFD_TAGS, Notes::Raf, true)
            .map_err(|e| e.within(format!("in the RAF's TIFF structure at byte {start}")))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::container::check;
    use crate::container::testutil::tiff;

    #[test]
    fn a_rafs_tiff_structures_are_walked() {
        // Fujifilm's header: big-endian pointers at bytes 84 (preview JPEG,
        // its TIFF 12 bytes in) and 100 (raw IFDs).
        let raf = |inner: &[u8], pointer: usize, skip: u32| {
            let mut b = b"FUJIFILMCCD-RAW 0201".to_vec();
            b.resize(112, 0);
            let at = 112 - skip;
            b[pointer..pointer + 4].copy_from_slice(&at.to_be_bytes());
            b.extend_from_slice(inner);
            b
        };
        let bad = tiff(&[(256, 3, 1, 4), (700, 4, 1000, 8)], 0, &[]);
        let good = tiff(&[(256, 3, 1, 4)], 0, &[]);
        for (pointer, skip) in [(84, 12), (100, 0)] {
            let e = check(&raf(&bad, pointer, skip)).unwrap_err().to_string();
            assert!(
                e.contains("past the end") && e.contains("RAF's TIFF structure at byte 112"),
                "{e}"
            );
            assert_eq!(check(&raf(&good, pointer, skip)), Ok(()));
        }
        // Pointers past the end or at something else are left to rawler.
        let mut b = raf(&good, 84, 12);
        b[84..88].copy_from_slice(&u32::MAX.to_be_bytes());
        b[100..104].copy_from_slice(&20u32.to_be_bytes());
        assert_eq!(check(&b), Ok(()));
    }
}
