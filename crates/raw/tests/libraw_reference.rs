//! The decode of canon550d_colorchart.dng must agree exactly with what LibRaw
//! 0.22.2 reads (../shared/data/raw/LIBRAW_REFERENCE.json).

mod common;

use pgrf_raw::{decode_file, pack_u16, Cfa, LevelOverrides};
use serde_json::Value;
use sha2::{Digest, Sha256};

#[test]
#[cfg_attr(not(shared_data), ignore = "needs ../shared/data")]
fn canon_550d_matches_libraw() {
    let data = common::data_dir();
    let reference: Value = serde_json::from_str(
        &std::fs::read_to_string(data.join("raw/LIBRAW_REFERENCE.json")).unwrap(),
    )
    .unwrap();
    let r = &reference["canon550d_colorchart.dng"];
    let f = decode_file(
        &data.join("raw/canon550d_colorchart.dng"),
        &LevelOverrides::default(),
    )
    .unwrap();

    let as_usize = |v: &Value| v.as_u64().unwrap() as usize;
    assert_eq!(
        (f.height, f.width),
        (
            as_usize(&r["visible_shape"][0]),
            as_usize(&r["visible_shape"][1])
        )
    );
    assert_eq!(
        f.sensor_origin,
        (
            as_usize(&r["visible_offset_top_left"][0]),
            as_usize(&r["visible_offset_top_left"][1])
        )
    );
    assert_eq!(
        f.sensor_size,
        (as_usize(&r["raw_shape"][0]), as_usize(&r["raw_shape"][1]))
    );
    assert_eq!(f.white as u64, r["white_level"].as_u64().unwrap());

    // LibRaw's black_level_per_channel and raw_pattern index colours by
    // color_desc "RGBG": 0 R, 1 G, 2 B, 3 second G. Our planes are R, G1, B, G2.
    let libraw_black: Vec<f32> = r["black_level_per_channel"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap() as f32)
        .collect();
    assert_eq!(
        f.black,
        [
            libraw_black[0],
            libraw_black[1],
            libraw_black[2],
            libraw_black[3]
        ]
    );

    let pattern = &r["raw_pattern"];
    let letter = |v: &Value| ["R", "G", "B", "G"][v.as_u64().unwrap() as usize];
    let cfa_name: String = [
        &pattern[0][0],
        &pattern[0][1],
        &pattern[1][0],
        &pattern[1][1],
    ]
    .into_iter()
    .map(letter)
    .collect();
    assert_eq!(f.cfa, cfa_name.parse::<Cfa>().unwrap());
    assert_eq!(f.cfa, Cfa::Rggb);

    // Exact pixels: SHA-256 of the visible mosaic as little-endian u16.
    let bytes: Vec<u8> = f.mosaic.iter().flat_map(|v| v.to_le_bytes()).collect();
    let digest = format!("{:x}", Sha256::digest(&bytes));
    assert_eq!(digest, r["visible_sha256_u16le"].as_str().unwrap());
    let sum: u64 = f.mosaic.iter().map(|&v| v as u64).sum();
    assert_eq!(sum, r["visible_sum"].as_u64().unwrap());
    assert_eq!(
        *f.mosaic.iter().min().unwrap() as u64,
        r["visible_min"].as_u64().unwrap()
    );
    assert_eq!(
        *f.mosaic.iter().max().unwrap() as u64,
        r["visible_max"].as_u64().unwrap()
    );
    for px in r["visible_pixels_row_col_value"].as_array().unwrap() {
        let (row, col, v) = (as_usize(&px[0]), as_usize(&px[1]), px[2].as_u64().unwrap());
        assert_eq!(f.at(row, col) as u64, v, "pixel ({row},{col})");
    }

    // White balance: LibRaw's cam_mul is unnormalised; compare ratios to green.
    let wb = f.wb.expect("as-shot white balance");
    let cam: Vec<f64> = r["camera_whitebalance"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!(
        (wb[0] as f64 - cam[0] / cam[1]).abs() < 1e-4,
        "{wb:?} vs {cam:?}"
    );
    assert!(
        (wb[2] as f64 - cam[2] / cam[1]).abs() < 1e-4,
        "{wb:?} vs {cam:?}"
    );

    // Packing puts the top-left red pixel at plane R (0,0) and the bottom-right
    // sample of the first cell in plane B.
    let p = pack_u16(&f).unwrap();
    assert_eq!(p[[0, 0, 0]], f.at(0, 0));
    assert_eq!(p[[1, 0, 0]], f.at(0, 1));
    assert_eq!(p[[2, 0, 0]], f.at(1, 1));
    assert_eq!(p[[3, 0, 0]], f.at(1, 0));
}

#[test]
#[cfg_attr(not(shared_data), ignore = "needs ../shared/data")]
fn level_overrides_replace_metadata() {
    let data = common::data_dir();
    let o = LevelOverrides {
        black: Some(vec![2000.0, 2001.0, 2002.0, 2003.0]),
        white: Some(16383),
    };
    let f = decode_file(&data.join("raw/canon550d_colorchart.dng"), &o).unwrap();
    assert_eq!(f.black, [2000.0, 2001.0, 2002.0, 2003.0]);
    assert_eq!(f.white, 16383);
}

#[test]
#[cfg_attr(not(shared_data), ignore = "needs ../shared/data")]
fn kodak_kdc_decodes_as_grbg() {
    let data = common::data_dir();
    let f = decode_file(&data.join("raw/kodak_dc50.kdc"), &LevelOverrides::default()).unwrap();
    assert_eq!(f.cfa, Cfa::Grbg);
    assert_eq!((f.width, f.height), (768, 512));
}
