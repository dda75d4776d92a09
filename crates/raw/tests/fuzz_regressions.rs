//! Inputs the fuzz targets found (fuzz/README.md), or that their triage
//! produced, kept as files under tests/fuzz_regressions/: each must be
//! refused with one line by the container check, before rawler sees it, and
//! the decode must be an error, not a panic, an abort or a hang.

use pgrf_raw::{container, decode_bytes, LevelOverrides};
use std::path::{Path, PathBuf};

/// Every committed input, with a part of the message it must be refused with.
const CASES: [(&str, &str); 11] = [
    // raw_decode, minimised: a RAF whose header points at a TIFF with an
    // entry of unknown type and count 2^32 - 1 (rawler allocated 4 GB for
    // its values before reading them; RAF containers were not checked).
    (
        "raf_embedded_tiff_4gb_entry.raf",
        "in the RAF's TIFF structure at byte 12",
    ),
    // Triage of the above, in a plain TIFF: an entry of unknown type was
    // taken to have no values at all, so its 4 GB were not checked.
    (
        "tiff_unknown_type_4gb_entry.dng",
        "tag 39321's 4294967295 values at byte 8 run past the end of the file",
    ),
    // raw_decode, minimised: a 22-byte MRW whose IFD (rawler reads it at
    // byte 8 when there is no TTW block) has an entry of unknown type and
    // count ~2^32 (4 GB allocated; MRW containers were not checked).
    ("mrw_ifd_4gb_entry.mrw", "in the MRW's TIFF block at byte 0"),
    // Triage of the above: a block length rawler's 32-bit `len + 8` wraps to
    // 0, so that it read the same block forever.
    ("mrw_block_length_wraps.mrw", "claims 4294967288 bytes"),
    // raw_decode, minimised: a 38-byte TIFF whose EXIF IFD pointer is 0.
    // The walk took 0 as "no IFD"; rawler reads the file header as an IFD of
    // 0x4949 entries, one of them of ~2^32 bytes: refused where rawler's
    // own reading of that IFD would allocate it.
    (
        "tiff_exif_ifd_at_offset_0.tif",
        "tag 0 claims 4294966389 values (4096 MiB), more than the file could hold",
    ),
    // Triage: one IFD reached 1,000 times through a SubIFDs list, each time
    // reading 4,000 strip-offset lists of 15,000 values (6e10 reads, most
    // of an hour) before anything was refused. rawler itself would hold
    // every copy of the lists it read, which is what refuses it first.
    (
        "tiff_revisited_ifd_long_strip_lists.dng",
        "its entries' values add up to more than 512 MiB",
    ),
    // raw_decode: a NEF whose MakerNote ("Nikon\0\x02", then a big-endian
    // TIFF its offsets count from) has an entry of count ~2^32 (rawler
    // allocated 4 GB parsing it; MakerNotes were not walked).
    (
        "nef_makernote_4gb_entry.nef",
        "4294967280 values at byte 16 run past the end of the file (in the MakerNote at byte 236, whose offsets count from byte 246)",
    ),
    // raw_decode: 19 bytes, a moov box holding a box of size 0, which
    // rawler read again forever, keeping a record of each (1.6 GB; every
    // file rawler does not know by its magic is parsed as BMFF boxes).
    (
        "bmff_vendor_boxes_3gb.cr3",
        "box at byte 8 claims 0 bytes, less than its 8-byte header",
    ),
    // raw_decode: a CR3 whose CMT3 box (Canon's MakerNote as TIFF) has
    // entries of counts up to ~3e9 (rawler allocated 3.1 GB for one).
    (
        "cr3_cmt_tiff_entry_3gb.cr3",
        "run past the end of the file (in the CR3's CMT3 box at byte 1744)",
    ),
    // raw_decode, with 96 bytes of junk after mdat cut off: a CR3 whose
    // CTMD sample (Canon's metadata, found through stsc, stsz and co64) has
    // a record claiming 2.6 GB, which rawler allocated before reading it.
    (
        "cr3_metadata_2.6gb.cr3",
        "the CTMD record at byte 51010 claims 2664171520 bytes",
    ),
    // raw_decode: a 737-byte QuickTake 150 file claiming 60726 x 43064
    // pixels (rawler allocated the 5.2 GB image before decoding any).
    (
        "qtk_150_5gb_dimensions.qtk",
        "the QuickTake header claims a 60726 x 43064 image (2615 megapixels)",
    ),
];

fn dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz_regressions")
}

#[test]
fn every_fuzz_regression_is_refused_by_the_container_check() {
    for (name, want) in CASES {
        let bytes = std::fs::read(dir().join(name)).unwrap();
        assert!(bytes.len() <= 64 * 1024, "{name}: keep regressions small");
        let reason = container::check(&bytes)
            .err()
            .unwrap_or_else(|| panic!("{name}: the container check accepted it"))
            .to_string();
        assert!(reason.contains(want), "{name}: {reason}");
        let err = decode_bytes(Path::new(name), &bytes, &LevelOverrides::default())
            .err()
            .unwrap_or_else(|| panic!("{name} decoded but should not"))
            .to_string();
        assert!(!err.contains('\n') && err.contains(name), "{name}: {err}");
        assert!(err.contains(want), "{name}: {err}");
    }
}

#[test]
fn every_committed_regression_file_is_listed() {
    let mut files: Vec<String> = std::fs::read_dir(dir())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    files.sort();
    let mut listed: Vec<String> = CASES.iter().map(|(n, _)| n.to_string()).collect();
    listed.sort();
    assert_eq!(files, listed);
}
