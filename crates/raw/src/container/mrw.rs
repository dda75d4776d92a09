//! Minolta's MRW container: a chain of blocks whose TTW block holds the
//! IFD rawler parses. The chain is checked here, for the step that would
//! make rawler loop; the IFD is walked by `tiff`.

use super::order::Order;
use super::tiff::walk_ifds;
use super::ContainerError;

/// A Minolta MRW is a chain of blocks (4-byte name, big-endian length) up to
/// the pixel data, whose offset minus 8 is at byte 4. rawler parses the IFD
/// at byte 8 of the last TTW block's contents, big-endian, without a TIFF
/// header (with no TTW block, at byte 8 of the file): that IFD is walked
/// as rawler finds it, and the block chain must not make rawler loop.
pub(super) fn check_mrw(bytes: &[u8]) -> Result<(), ContainerError> {
    let be = Order(false);
    let Some(data) = be.u32(bytes, 4).map(|v| v as u64 + 8) else {
        return Ok(());
    };
    let mut tiff = 0u64;
    let mut at = 8u64;
    while at + 20 < data {
        let (Some(tag), Some(len)) = (be.u32(bytes, at as usize), be.u32(bytes, at as usize + 4))
        else {
            break;
        };
        // rawler steps by `len + 8` in 32 bits: these lengths wrap to a
        // step of 0 and it would read the same block forever.
        if len > u32::MAX - 8 {
            return Err(ContainerError::malformed(format!(
                "malformed MRW structure: the block at byte {at} claims {len} bytes"
            )));
        }
        if tag == 0x0054_5457 {
            tiff = at + 8;
        }
        at += len as u64 + 8;
    }
    let Some(block) = usize::try_from(tiff).ok().and_then(|t| bytes.get(t..)) else {
        return Ok(());
    };
    walk_ifds(block, be, 8, &[], true)
        .map(drop)
        .map_err(|e| e.within(format!("in the MRW's TIFF block at byte {tiff}")))
}

#[cfg(test)]
mod tests {
    use super::super::check;

    /// An MRW: magic, the data offset minus 8, a PRD block, then a TTW
    /// block holding 8 bytes of header and a big-endian IFD of one entry
    /// (tag 256, LONG, `count` values at byte `value` of the block).
    fn mrw(count: u32, value: u32, ttw_len: u32) -> Vec<u8> {
        let mut ifd = b"MM\0*\0\0\0\x08".to_vec();
        ifd.extend_from_slice(&1u16.to_be_bytes());
        for v in [256u16.to_be_bytes().as_slice(), &4u16.to_be_bytes()] {
            ifd.extend_from_slice(v);
        }
        ifd.extend_from_slice(&count.to_be_bytes());
        ifd.extend_from_slice(&value.to_be_bytes());
        ifd.extend_from_slice(&0u32.to_be_bytes());
        ifd.resize(64, 0);
        let mut b = b"\0MRM".to_vec();
        let blocks = 8 + 8 + 8 + ifd.len();
        b.extend_from_slice(&(blocks as u32).to_be_bytes());
        b.extend_from_slice(b"\0PRD");
        b.extend_from_slice(&0u32.to_be_bytes());
        b.extend_from_slice(b"\0TTW");
        b.extend_from_slice(&ttw_len.to_be_bytes());
        b.extend_from_slice(&ifd);
        b.resize(b.len() + 64, 0);
        b
    }

    #[test]
    fn the_ttw_blocks_ifd_and_the_block_chain_are_checked() {
        // One value sits inline; eight lie inside the block.
        assert_eq!(check(&mrw(1, 7, 64)), Ok(()));
        assert_eq!(check(&mrw(8, 24, 64)), Ok(()));
        // A count whose values run past the file.
        let e = check(&mrw(0x4000_0000, 24, 64)).unwrap_err().to_string();
        assert!(
            e.contains("past the end") && e.contains("MRW's TIFF block"),
            "{e}"
        );
        // A block length rawler's 32-bit step would wrap to 0.
        let e = check(&mrw(1, 7, u32::MAX - 4)).unwrap_err().to_string();
        assert!(e.contains("claims 4294967291 bytes"), "{e}");
    }
}
