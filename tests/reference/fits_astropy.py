#!/usr/bin/env python3
"""FITS interoperability evidence for pgrf_raw::fits, with astropy.

Two directions, so that the Rust test suite never needs Python:

(a) astropy writes, pgrf reads.  `python3 tests/reference/fits_astropy.py write`
    writes three small fixtures into crates/raw/tests/data/fits/ and prints
    their pixel values; crates/raw/tests/fits.rs reads the committed files
    and asserts those numbers as literals:

      astropy_rggb_u16.fits   6x4 uint16 (astropy stores it as BITPIX 16,
                              BZERO 32768), BAYERPAT/ROWORDER/EXPTIME/...
      astropy_mono_f32.fits   6x4 float32 in 0..1 (a Siril-style normalised
                              frame; pgrf scales it by 65535)
      astropy_fpack_rice.fits the same uint16 image tile-compressed (RICE_1)
                              in a binary-table extension behind an empty
                              primary HDU (what fpack writes; pgrf refuses it
                              and names funpack)

(b) pgrf writes, astropy reads.  Run once:

      PGRF_FITS_ASTROPY_DIR=/tmp/pgrf-fits \\
          cargo test -p pgrf-raw --test fits pgrf_files_for_astropy
      python3 tests/reference/fits_astropy.py check /tmp/pgrf-fits

    The Rust test (a no-op without the variable) writes pgrf_bayer_u16.fits
    (7x5, encode_fits_u16) and pgrf_master_f32.fits (5x3, encode_fits_f32);
    this script opens them with astropy, runs astropy's FITS-standard
    verification (`verify("exception")`), and compares every pixel and
    header value with the formulas below.

Run on 2026-11-25 with astropy 8.0.2 and numpy 2.4.6 (pip install astropy numpy), the
check printed:

    pgrf_bayer_u16.fits: BITPIX 16 BZERO 32768 -> uint16 (5, 7), 35 pixels equal
    pgrf_bayer_u16.fits: header EXPTIME=120.5 EGAIN=1.25 GAIN=100 CCD-TEMP=-15.5 ISOSPEED=800 INSTRUME="QHY 'test' 268C" BAYERPAT=GRBG XBAYROFF=1 YBAYROFF=0 ROWORDER=TOP-DOWN DATE-OBS=2026-01-02T03:04:05.500 ok
    pgrf_master_f32.fits: BITPIX -32 -> float32 (3, 5), 15 pixels equal
    pgrf_master_f32.fits: header IMAGETYP=Master Dark NCOMBINE=16 ok
    all checks passed

Pixel formulas (row r, column c, as stored):
    pgrf_bayer_u16:  (r * 7 + c) * 9973 % 65536
    pgrf_master_f32: 1000.125 + 0.25 * (r * 5 + c)
"""

import sys
from pathlib import Path

import numpy as np
from astropy.io import fits

ROOT = Path(__file__).resolve().parents[2]
FIXTURES = ROOT / "crates" / "raw" / "tests" / "data" / "fits"


def u16_pixels():
    i, j = np.mgrid[0:4, 0:6]
    v = ((i * 6 + j) * 2731) % 65536
    v[0, 0] = 0
    v[3, 5] = 65535
    return v.astype(np.uint16)


def write():
    FIXTURES.mkdir(parents=True, exist_ok=True)

    data = u16_pixels()
    hdu = fits.PrimaryHDU(data)
    h = hdu.header
    h["BAYERPAT"] = ("RGGB", "Bayer pattern, top-down")
    h["ROWORDER"] = ("TOP-DOWN", "order of the rows in the image array")
    h["XBAYROFF"] = (0, "X offset of Bayer array")
    h["YBAYROFF"] = (0, "Y offset of Bayer array")
    h["EXPTIME"] = (30.0, "[s] exposure time")
    h["EGAIN"] = (0.8, "electrons per ADU")
    h["GAIN"] = (120, "camera gain setting")
    h["CCD-TEMP"] = (-10.0, "[C] sensor temperature")
    h["INSTRUME"] = ("ZWO ASI294MC Pro", "camera")
    h["DATE-OBS"] = ("2024-03-01T21:15:00.000", "start of exposure, UTC")
    path = FIXTURES / "astropy_rggb_u16.fits"
    hdu.writeto(path, overwrite=True)
    print(f"{path.name} ({path.stat().st_size} bytes): uint16 {data.shape}, rows as stored:")
    for row in data:
        print("   ", ", ".join(str(int(x)) for x in row))

    i, j = np.mgrid[0:4, 0:6]
    f = ((i * 6 + j + 1) / np.float32(25)).astype(np.float32)
    hdu = fits.PrimaryHDU(f)
    hdu.header["EXPTIME"] = (5.0, "[s]")
    path = FIXTURES / "astropy_mono_f32.fits"
    hdu.writeto(path, overwrite=True)
    scaled = np.round(f.astype(np.float64) * 65535).astype(np.int64)
    frac = np.abs(f.astype(np.float64) * 65535 - np.floor(f.astype(np.float64) * 65535) - 0.5)
    assert frac.min() > 1e-6, "a value lies on a rounding tie"
    print(f"{path.name} ({path.stat().st_size} bytes): float32 {f.shape}, as read by astropy:")
    for row in fits.getdata(path):
        print("   ", ", ".join(repr(float(x)) for x in row))
    print("  round(v * 65535), rows as stored:")
    for row in scaled:
        print("   ", ", ".join(str(int(x)) for x in row))

    comp = fits.CompImageHDU(data, compression_type="RICE_1")
    path = FIXTURES / "astropy_fpack_rice.fits"
    fits.HDUList([fits.PrimaryHDU(), comp]).writeto(path, overwrite=True)
    with fits.open(path) as hdul:
        assert hdul[0].header["NAXIS"] == 0
        assert (hdul[1].data == data).all()
    print(f"{path.name} ({path.stat().st_size} bytes): empty primary + RICE_1 BINTABLE (ZIMAGE = T)")


def check(folder):
    folder = Path(folder)
    ok = True

    path = folder / "pgrf_bayer_u16.fits"
    with fits.open(path) as hdul:
        hdul.verify("exception")
        h = hdul[0].header
        d = hdul[0].data
        r, c = np.mgrid[0:5, 0:7]
        want = ((r * 7 + c) * 9973) % 65536
        same = d.dtype == np.uint16 and d.shape == (5, 7) and (d.astype(np.int64) == want).all()
        ok &= bool(same)
        print(f"{path.name}: BITPIX {h['BITPIX']} BZERO {h['BZERO']} -> {d.dtype} {d.shape}, "
              f"{int((d.astype(np.int64) == want).sum())} pixels equal")
        expect = {
            "EXPTIME": 120.5, "EGAIN": 1.25, "GAIN": 100, "CCD-TEMP": -15.5, "ISOSPEED": 800,
            "INSTRUME": "QHY 'test' 268C", "BAYERPAT": "GRBG", "XBAYROFF": 1, "YBAYROFF": 0,
            "ROWORDER": "TOP-DOWN", "DATE-OBS": "2026-01-02T03:04:05.500",
        }
        good = all(h[k] == v for k, v in expect.items())
        ok &= good
        shown = " ".join(
            f'{k}="{h[k]}"' if k == "INSTRUME" else f"{k}={h[k]}" for k in expect
        )
        print(f"{path.name}: header {shown} {'ok' if good else 'MISMATCH'}")

    path = folder / "pgrf_master_f32.fits"
    with fits.open(path) as hdul:
        hdul.verify("exception")
        h = hdul[0].header
        d = hdul[0].data
        r, c = np.mgrid[0:3, 0:5]
        want = (1000.125 + 0.25 * (r * 5 + c)).astype(np.float32)
        same = d.dtype == np.dtype(">f4") and d.shape == (3, 5) and (d == want).all()
        ok &= bool(same)
        print(f"{path.name}: BITPIX {h['BITPIX']} -> {d.dtype.name} {d.shape}, "
              f"{int((d == want).sum())} pixels equal")
        good = h["IMAGETYP"] == "Master Dark" and h["NCOMBINE"] == 16
        ok &= good
        print(f"{path.name}: header IMAGETYP={h['IMAGETYP']} NCOMBINE={h['NCOMBINE']} "
              f"{'ok' if good else 'MISMATCH'}")

    print("all checks passed" if ok else "SOME CHECKS FAILED")
    return 0 if ok else 1


if __name__ == "__main__":
    if len(sys.argv) >= 2 and sys.argv[1] == "write":
        write()
    elif len(sys.argv) == 3 and sys.argv[1] == "check":
        sys.exit(check(sys.argv[2]))
    else:
        sys.exit(__doc__)
