//! decode -> write DNG -> decode must give identical pixels, levels and metadata.

mod common;

use pgrf_raw::{
    decode_file, encode_dng, write_dng, Cfa, ColorMatrix, Compression, DngOptions, LevelOverrides,
    RawFrame,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn assert_same(a: &RawFrame, b: &RawFrame) {
    assert_eq!((a.width, a.height), (b.width, b.height));
    assert_eq!(a.cfa, b.cfa);
    assert_eq!(a.mono, b.mono);
    assert_eq!(a.noise_profile, b.noise_profile);
    assert_eq!(a.black, b.black);
    assert_eq!(a.white, b.white);
    assert!(a.mosaic == b.mosaic, "pixels differ");
    assert_eq!(a.iso, b.iso);
    match (a.exposure_s, b.exposure_s) {
        (Some(x), Some(y)) => assert!((x - y).abs() <= 1e-9 * x, "{x} vs {y}"),
        (x, y) => assert_eq!(x, y),
    }
    match (a.wb, b.wb) {
        (Some(x), Some(y)) => {
            for c in 0..3 {
                assert!((x[c] - y[c]).abs() < 1e-5 * x[c], "wb {x:?} vs {y:?}")
            }
        }
        (x, y) => assert_eq!(x, y),
    }
    // Matrices are stored in 1/10000 steps: equal to that precision, and the
    // same illuminants in the same order.
    assert_eq!(a.color_matrices.len(), b.color_matrices.len());
    for (x, y) in a.color_matrices.iter().zip(&b.color_matrices) {
        assert_eq!(x.illuminant, y.illuminant);
        for (r, s) in x
            .xyz_to_cam
            .iter()
            .flatten()
            .zip(y.xyz_to_cam.iter().flatten())
        {
            assert!((r - s).abs() < 0.5e-4, "{x:?} vs {y:?}");
        }
    }
    assert_eq!(a.make, b.make);
    assert_eq!(a.orientation, b.orientation);
    assert_eq!(a.model, b.model);
}

#[test]
#[cfg_attr(not(shared_data), ignore = "needs ../shared/data")]
fn canon_550d_survives_dng_round_trip_both_compressions() {
    let data = common::data_dir();
    let src = decode_file(
        &data.join("raw/canon550d_colorchart.dng"),
        &LevelOverrides::default(),
    )
    .unwrap();
    let dir = common::scratch("dng550d");
    for compression in [Compression::Lossless, Compression::Uncompressed] {
        let out = dir.join(format!("{compression:?}.dng"));
        write_dng(
            &src,
            &out,
            &DngOptions {
                compression,
                ..Default::default()
            },
        )
        .unwrap();
        let back = decode_file(&out, &LevelOverrides::default()).unwrap();
        assert_same(&src, &back);
        assert_eq!(back.sensor_origin, (0, 0));
        let size = std::fs::metadata(&out).unwrap().len() as usize;
        if compression == Compression::Lossless {
            assert!(
                size < src.mosaic.len() * 2,
                "lossless DNG not smaller than raw samples: {size}"
            );
        }
    }
}

fn synthetic(cfa: Cfa, w: usize, h: usize, seed: u64) -> RawFrame {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mosaic = (0..w * h).map(|_| rng.random_range(0..16384u16)).collect();
    let mut f =
        RawFrame::from_mosaic(w, h, mosaic, cfa, [512.0, 511.5, 513.0, 510.0], 16383).unwrap();
    f.iso = Some(3200);
    f.exposure_s = Some(1.0 / 30.0);
    f.wb = Some([2.1, 1.0, 1.55]);
    f.noise_profile = Some(vec![[2.5e-4, 3.1e-6], [1.9e-4, 2.7e-6], [2.8e-4, 3.3e-6]]);
    // The A7S2's two published matrices: tungsten (A) in slot 1, D65 in slot 2.
    f.color_matrices = vec![
        ColorMatrix {
            xyz_to_cam: [
                [0.6263, -0.1964, 0.0102],
                [-0.4375, 1.2428, 0.2171],
                [-0.066, 0.1559, 0.7146],
            ],
            illuminant: "A".into(),
        },
        ColorMatrix {
            xyz_to_cam: [
                [0.5838, -0.143, -0.0246],
                [-0.3497, 1.1477, 0.2297],
                [-0.0748, 0.1885, 0.5778],
            ],
            illuminant: "D65".into(),
        },
    ];
    f.make = "Sony".into();
    f.model = "ILCE-7SM2".into();
    f.orientation = 6;
    f
}

#[test]
fn every_cfa_phase_and_odd_sizes_round_trip() {
    let dir = common::scratch("dngphases");
    for (k, cfa) in Cfa::ALL.into_iter().enumerate() {
        for (w, h) in [(64, 48), (37, 23)] {
            let f = synthetic(cfa, w, h, 11 + k as u64);
            for compression in [Compression::Lossless, Compression::Uncompressed] {
                let out = dir.join(format!("{cfa}-{w}-{compression:?}.dng"));
                write_dng(
                    &f,
                    &out,
                    &DngOptions {
                        compression,
                        ..Default::default()
                    },
                )
                .unwrap();
                let back = decode_file(&out, &LevelOverrides::default())
                    .unwrap_or_else(|e| panic!("{cfa} {w}x{h} {compression:?}: {e}"));
                assert_same(&f, &back);
            }
        }
    }
}

/// A monochrome frame is written as a one-sample BlackIsZero DNG and comes
/// back monochrome with the same pixels, per-sub-lattice blacks and
/// metadata, without colour (no white balance, no matrices).
#[test]
fn monochrome_frames_round_trip() {
    let dir = common::scratch("dngmono");
    for (w, h) in [(64, 48), (37, 23)] {
        let mut f = synthetic(Cfa::Rggb, w, h, 41);
        f.mono = true;
        f.wb = None;
        f.color_matrices.clear();
        f.black = [100.0, 101.0, 99.0, 100.5];
        // One plane: one (S, O) pair.
        f.noise_profile = Some(vec![[2.5e-4, 3.1e-6]]);
        for compression in [Compression::Lossless, Compression::Uncompressed] {
            let out = dir.join(format!("mono-{w}-{compression:?}.dng"));
            write_dng(
                &f,
                &out,
                &DngOptions {
                    compression,
                    ..Default::default()
                },
            )
            .unwrap();
            let back = decode_file(&out, &LevelOverrides::default())
                .unwrap_or_else(|e| panic!("mono {w}x{h} {compression:?}: {e}"));
            assert!(back.mono, "{w}x{h} {compression:?} came back with a CFA");
            assert_eq!(back.layout(), "mono");
            assert_same(&f, &back);
        }
    }
}

#[test]
fn encoding_is_deterministic() {
    let f = synthetic(Cfa::Gbrg, 40, 30, 5);
    let a = encode_dng(&f, &DngOptions::default()).unwrap();
    let b = encode_dng(&f, &DngOptions::default()).unwrap();
    assert_eq!(a, b);
}

#[test]
fn missing_output_folder_writes_nothing() {
    let dir = common::scratch("dngmissing");
    let f = synthetic(Cfa::Rggb, 8, 8, 1);
    let err = write_dng(&f, &dir.join("no/such/out.dng"), &DngOptions::default()).unwrap_err();
    assert!(err.to_string().contains("does not exist"), "{err}");
    assert!(!dir.join("no").exists());
}

/// A frame with a masked strip: 32 columns whose per-plane values are
/// `base[plane]` +- 1 in a checkerboard of 2x2 cells (mean exactly `base`).
fn with_strip(cfa: Cfa, w: usize, h: usize, base: [u16; 4]) -> RawFrame {
    let mut f = synthetic(cfa, w, h, 9);
    let columns = 32;
    let values = (0..h)
        .flat_map(|r| (0..columns).map(move |c| (r, c)))
        .map(|(r, c)| base[cfa.plane_at(r, c)] + 2 * ((r / 2 + c / 2) % 2) as u16 - 1)
        .collect();
    let strip = pgrf_raw::masked::MaskedStrip { columns, values };
    f.masked = pgrf_raw::masked::Masked::of_strip(strip, h, cfa);
    f
}

/// The strip is written as the readout's first columns, declared in
/// MaskedAreas, and reads back bit for bit with its per-plane level (the
/// exact means, 600 / 602 / 604 / 606 DN) beside the same visible pixels.
/// LibRaw (0.22.2, rawpy 0.28) reads the same file as a 128-column readout
/// with `left_margin` 32, `raw_image_visible` summing to 50,358,028 (first
/// row 8266, 1869, 15597, 12812) and the strip to 1,234,944, and takes its
/// black from the masked pixels as pgrf does, plane by plane:
/// `black_level_per_channel` [600, 602, 604, 606] (R, G, B, G2), where the
/// BlackLevel tag says 512 / 511.5 / 513 / 510.
#[test]
fn a_masked_strip_round_trips_beside_the_visible_pixels() {
    let base = [600, 602, 604, 606];
    let f = with_strip(Cfa::Grbg, 96, 64, base);
    let m = f.masked.clone().expect("measured");
    assert_eq!(m.level, base.map(f32::from));
    assert_eq!(m.pixels, 32 * 64 / 4);
    let dir = common::scratch("dngmasked");
    let path = dir.join("masked.dng");
    write_dng(&f, &path, &DngOptions::default()).unwrap();
    if std::env::var_os("PGRF_KEEP_MASKED_DNG").is_some() {
        std::fs::copy(&path, std::env::temp_dir().join("pgrf-masked.dng")).unwrap();
    }
    let g = decode_file(&path, &LevelOverrides::default()).unwrap();
    assert_eq!(g.mosaic, f.mosaic);
    let sum = |v: &[u16]| v.iter().map(|&x| x as u64).sum::<u64>();
    assert_eq!(
        (sum(&g.mosaic), &g.mosaic[..4]),
        (50_358_028, &[8266, 1869, 15597, 12812][..])
    );
    let strip = m.strip.as_ref().unwrap();
    assert_eq!(sum(&strip.values), 1_234_944);
    assert_eq!(g.black, f.black);
    assert_eq!(g.masked, f.masked);
    assert_eq!((g.sensor_origin, g.sensor_size), ((0, 32), (64, 128)));
    // A frame cropped from it keeps the level, not the strip; new pixels
    // keep neither.
    let c = g.crop(2, 2, 32, 32).unwrap();
    assert_eq!(
        c.masked.as_ref().map(|m| (m.level, m.strip.is_none())),
        Some((m.level, true))
    );
}

/// Every DNG pgrf writes carries the NewRawImageDigest of DNG 1.4 (MD5 of
/// the samples in row-scan order, 16 bits little-endian). The value is
/// checked against Python's hashlib over the same samples (computed
/// independently: `hashlib.md5(b"".join(struct.pack("<H", (i * 37 + 11) %
/// 4096 + 600) for i in range(48 * 32)))`). On an enhance output of the
/// 550D chart (1734 x 1156) the stored digest was also checked equal to
/// `hashlib.md5` of LibRaw's `raw_image` (rawpy 0.28), as the DNG spec
/// defines it. A pixel changed after writing is caught
/// ([`pgrf_raw::pixels_intact`]); the untouched file passes.
#[test]
fn every_dng_states_its_pixels_digest() {
    let mosaic: Vec<u16> = (0..48 * 32)
        .map(|i| ((i * 37 + 11) % 4096 + 600) as u16)
        .collect();
    let f = RawFrame::from_mosaic(48, 32, mosaic.clone(), Cfa::Rggb, [512.0; 4], 16383).unwrap();
    let hex = |d: [u8; 16]| d.iter().map(|b| format!("{b:02x}")).collect::<String>();
    assert_eq!(
        hex(pgrf_raw::raw_image_digest(&mosaic)),
        "64558e02080403d8942aabb683305a92"
    );
    assert_eq!(
        hex(pgrf_raw::raw_image_digest(&[1, 2])),
        "99ffb3d9eeadc24aa4f9b13530176bf8"
    );
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("pgrf-digest");
    std::fs::create_dir_all(&dir).unwrap();
    for compression in [Compression::Lossless, Compression::Uncompressed] {
        let path = dir.join("d.dng");
        write_dng(
            &f,
            &path,
            &DngOptions {
                compression,
                ..Default::default()
            },
        )
        .unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let stored = pgrf_raw::container::raw_digest(&bytes).expect("a NewRawImageDigest");
        assert_eq!(hex(stored), "64558e02080403d8942aabb683305a92");
        let back = decode_file(&path, &LevelOverrides::default()).unwrap();
        assert!(pgrf_raw::pixels_intact(&bytes, &back));
        let mut changed = back.clone();
        changed.mosaic[700] ^= 1;
        assert!(!pgrf_raw::pixels_intact(&bytes, &changed));
    }
    std::fs::remove_dir_all(&dir).ok();
}
