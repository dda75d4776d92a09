#!/usr/bin/env python3
"""Every FITS file pgrf writes, checked with astropy and ccdproc (issue 39).

crates/calib/tests/fits_headers.rs writes, from virtual-sensor stacks whose
frames carry a ramp of 4 DN per stored row, the calibration masters
(`pgrf calibrate --masters`), a frame written back from a decoded input
(`pgrf convert`) and a virtual-sensor frame (`pgrf simulate-sensor`), for
inputs stored four ways: no ROWORDER ("none", bottom-up by the FITS
convention), BOTTOM-UP, TOP-DOWN, and a BOTTOM-UP colour (RGGB) sensor.
Run:

    PGRF_FITS_HEADERS_DIR=/tmp/pgrf-fits-headers \\
        cargo test -p pgrf-calib --test fits_headers
    python3 tests/reference/fits_headers_astropy.py /tmp/pgrf-fits-headers

For every file: astropy's FITS-standard verification (`verify("exception")`).
Masters: ROWORDER is the input's (BOTTOM-UP where the input had none), no
SATURATE, BITPIX -32 with samples in [0, 1], the stored rows' means rise by
4 DN per row as the input's do (the master is not upside down), and
ccdproc.subtract_bias of the input bias frame with the master bias leaves no
ramp (slope within 0.1 DN/row; an upside-down master would leave 8). The
frame written back: the same ROWORDER, SATURATE = 65535 and the input's
samples exactly; for the colour case BAYERPAT read with ROWORDER the way
Siril does gives the input's stored phase. The simulated frame: TOP-DOWN,
SATURATE = 16383.

Run on 2026-11-27 with astropy 8.0.2, ccdproc 2.5.1, numpy 2.4.6; it printed:

    none/master_bias.fits: ROWORDER=BOTTOM-UP SATURATE absent BITPIX -32 samples 0.00766..0.01082 row slope 4.003 DN/row (input 3.998)
    none/master_dark_10s.fits: ROWORDER=BOTTOM-UP SATURATE absent BITPIX -32 samples 0.00763..0.01262 row slope 3.992 DN/row (input 3.998)
    none/master_dark_20s.fits: ROWORDER=BOTTOM-UP SATURATE absent BITPIX -32 samples 0.00754..0.01363 row slope 3.978 DN/row (input 3.998)
    none/master_flat_1s.fits: ROWORDER=BOTTOM-UP SATURATE absent BITPIX -32 samples 0.05214..0.06041 row slope 3.931 DN/row (input 3.998)
    none/master_flat_3s.fits: ROWORDER=BOTTOM-UP SATURATE absent BITPIX -32 samples 0.14210..0.15649 row slope 3.793 DN/row (input 3.998)
    none: ccdproc.subtract_bias(input, master_bias) row slope -0.0050 DN/row (the master upside down would leave 8.001)
    none/converted.fits: ROWORDER=BOTTOM-UP SATURATE=65535 3072 samples equal to the input's
    bottom-up/master_bias.fits: ROWORDER=BOTTOM-UP SATURATE absent BITPIX -32 samples 0.00766..0.01082 row slope 4.003 DN/row (input 3.998)
    bottom-up/master_dark_10s.fits: ROWORDER=BOTTOM-UP SATURATE absent BITPIX -32 samples 0.00763..0.01262 row slope 3.992 DN/row (input 3.998)
    bottom-up/master_dark_20s.fits: ROWORDER=BOTTOM-UP SATURATE absent BITPIX -32 samples 0.00754..0.01363 row slope 3.978 DN/row (input 3.998)
    bottom-up/master_flat_1s.fits: ROWORDER=BOTTOM-UP SATURATE absent BITPIX -32 samples 0.05214..0.06041 row slope 3.931 DN/row (input 3.998)
    bottom-up/master_flat_3s.fits: ROWORDER=BOTTOM-UP SATURATE absent BITPIX -32 samples 0.14210..0.15649 row slope 3.793 DN/row (input 3.998)
    bottom-up: ccdproc.subtract_bias(input, master_bias) row slope -0.0050 DN/row (the master upside down would leave 8.001)
    bottom-up/converted.fits: ROWORDER=BOTTOM-UP SATURATE=65535 3072 samples equal to the input's
    top-down/master_bias.fits: ROWORDER=TOP-DOWN SATURATE absent BITPIX -32 samples 0.00766..0.01082 row slope 4.003 DN/row (input 3.998)
    top-down/master_dark_10s.fits: ROWORDER=TOP-DOWN SATURATE absent BITPIX -32 samples 0.00763..0.01262 row slope 3.992 DN/row (input 3.998)
    top-down/master_dark_20s.fits: ROWORDER=TOP-DOWN SATURATE absent BITPIX -32 samples 0.00754..0.01363 row slope 3.978 DN/row (input 3.998)
    top-down/master_flat_1s.fits: ROWORDER=TOP-DOWN SATURATE absent BITPIX -32 samples 0.05214..0.06041 row slope 3.931 DN/row (input 3.998)
    top-down/master_flat_3s.fits: ROWORDER=TOP-DOWN SATURATE absent BITPIX -32 samples 0.14210..0.15649 row slope 3.793 DN/row (input 3.998)
    top-down: ccdproc.subtract_bias(input, master_bias) row slope -0.0050 DN/row (the master upside down would leave 8.001)
    top-down/converted.fits: ROWORDER=TOP-DOWN SATURATE=65535 3072 samples equal to the input's
    colour-bottom-up/master_bias.fits: ROWORDER=BOTTOM-UP SATURATE absent BITPIX -32 samples 0.00766..0.01082 row slope 4.003 DN/row (input 3.998)
    colour-bottom-up/master_dark_10s.fits: ROWORDER=BOTTOM-UP SATURATE absent BITPIX -32 samples 0.00763..0.01262 row slope 3.992 DN/row (input 3.998)
    colour-bottom-up/master_dark_20s.fits: ROWORDER=BOTTOM-UP SATURATE absent BITPIX -32 samples 0.00754..0.01363 row slope 3.978 DN/row (input 3.998)
    colour-bottom-up/master_flat_1s.fits: ROWORDER=BOTTOM-UP SATURATE absent BITPIX -32 samples 0.05214..0.06041 row slope 3.931 DN/row (input 3.998)
    colour-bottom-up/master_flat_3s.fits: ROWORDER=BOTTOM-UP SATURATE absent BITPIX -32 samples 0.14210..0.15649 row slope 3.793 DN/row (input 3.998)
    colour-bottom-up: ccdproc.subtract_bias(input, master_bias) row slope -0.0050 DN/row (the master upside down would leave 8.001)
    colour-bottom-up/converted.fits: ROWORDER=BOTTOM-UP SATURATE=65535 3072 samples equal to the input's; BAYERPAT=RGGB -> stored phase GBRG (input GBRG); masters' stored phase GBRG
    simulated.fits: ROWORDER=TOP-DOWN SATURATE=16383
    all checks passed
"""

import sys
from pathlib import Path

import numpy as np
from astropy.io import fits

RAMP = 4.0
CASES = {
    "none": "BOTTOM-UP",
    "bottom-up": "BOTTOM-UP",
    "top-down": "TOP-DOWN",
    "colour-bottom-up": "BOTTOM-UP",
}


def fail(msg):
    print("FAILED:", msg)
    sys.exit(1)


def open_verified(path):
    hdul = fits.open(path)
    hdul.verify("exception")
    return hdul


def row_slope(data):
    """Least-squares slope of the stored rows' means over the row index, DN/row."""
    means = data.astype(np.float64).mean(axis=1)
    rows = np.arange(len(means))
    return np.polyfit(rows, means, 1)[0]


def stored_phase(header):
    """The Bayer phase of stored pixel (0, 0): BAYERPAT seen top-down,
    shifted by YBAYROFF and, for BOTTOM-UP, by (NAXIS2 - 1) rows (Siril's
    adjust_Bayer_pattern), and by XBAYROFF columns."""
    pattern = header["BAYERPAT"].strip()
    dy = int(header.get("YBAYROFF", 0)) % 2
    if header.get("ROWORDER", "TOP-DOWN").strip() == "BOTTOM-UP":
        dy = (dy + header["NAXIS2"] - 1) % 2
    dx = int(header.get("XBAYROFF", 0)) % 2
    cell = [[pattern[0], pattern[1]], [pattern[2], pattern[3]]]
    return "".join(cell[(r + dy) % 2][(c + dx) % 2] for r in range(2) for c in range(2))


def check_case(d, want):
    import ccdproc
    from astropy import units as u

    inp = open_verified(d / "input_bias.fits")
    in_data = inp[0].data.astype(np.float64)
    in_slope = row_slope(in_data)
    if abs(in_slope - RAMP) > 0.1 * RAMP:
        fail(f"{d.name}: input ramp {in_slope:.3f} DN/row")
    masters = sorted(d.glob("master_*.fits"))
    if len(masters) != 5:
        fail(f"{d.name}: {len(masters)} masters")
    for m in masters:
        h = open_verified(m)[0]
        row = h.header.get("ROWORDER")
        if row != want:
            fail(f"{d.name}/{m.name}: ROWORDER {row!r}, want {want}")
        if "SATURATE" in h.header:
            fail(f"{d.name}/{m.name}: SATURATE on normalised data")
        if h.header["BITPIX"] != -32:
            fail(f"{d.name}/{m.name}: BITPIX {h.header['BITPIX']}")
        lo, hi = float(h.data.min()), float(h.data.max())
        if not (0.0 <= lo and hi <= 1.0):
            fail(f"{d.name}/{m.name}: samples {lo}..{hi} outside [0, 1]")
        slope = row_slope(h.data * 65535.0)
        if abs(slope - RAMP) > 0.1 * RAMP:
            fail(f"{d.name}/{m.name}: rows rise {slope:.3f} DN/row, want {RAMP}")
        print(
            f"{d.name}/{m.name}: ROWORDER={row} SATURATE absent BITPIX -32 "
            f"samples {lo:.5f}..{hi:.5f} row slope {slope:.3f} DN/row (input {in_slope:.3f})"
        )
    # The master bias subtracted from the input bias with ccdproc: no ramp left.
    master_bias = fits.getdata(d / "master_bias.fits").astype(np.float64) * 65535.0
    raw = ccdproc.CCDData(in_data, unit=u.adu)
    bias = ccdproc.CCDData(master_bias, unit=u.adu)
    left = ccdproc.subtract_bias(raw, bias)
    residual = row_slope(np.asarray(left.data))
    flipped = row_slope(in_data - master_bias[::-1])
    if abs(residual) > 0.1:
        fail(f"{d.name}: bias-subtracted rows still rise {residual:.3f} DN/row")
    print(
        f"{d.name}: ccdproc.subtract_bias(input, master_bias) row slope {residual:.4f} DN/row "
        f"(the master upside down would leave {flipped:.3f})"
    )
    conv = open_verified(d / "converted.fits")[0]
    if conv.header.get("ROWORDER") != want:
        fail(f"{d.name}/converted: ROWORDER {conv.header.get('ROWORDER')!r}")
    if conv.header.get("SATURATE") != 65535:
        fail(f"{d.name}/converted: SATURATE {conv.header.get('SATURATE')!r}")
    same = np.array_equal(conv.data.astype(np.int64), inp[0].data.astype(np.int64))
    if not same:
        fail(f"{d.name}/converted: samples differ from the input's")
    line = (
        f"{d.name}/converted.fits: ROWORDER={conv.header['ROWORDER']} SATURATE={conv.header['SATURATE']} "
        f"{conv.data.size} samples equal to the input's"
    )
    if "BAYERPAT" in inp[0].header:
        a, b = stored_phase(inp[0].header), stored_phase(conv.header)
        if a != b:
            fail(f"{d.name}/converted: stored phase {b}, input {a}")
        line += f"; BAYERPAT={conv.header['BAYERPAT']} -> stored phase {b} (input {a})"
        for m in masters:
            c = stored_phase(fits.getheader(m))
            if c != a:
                fail(f"{d.name}/{m.name}: stored phase {c}, input {a}")
        line += f"; masters' stored phase {a}"
    print(line)


def main():
    if len(sys.argv) != 2:
        fail("usage: fits_headers_astropy.py DIR (written by the Rust test)")
    root = Path(sys.argv[1])
    for case, want in CASES.items():
        check_case(root / case, want)
    sim = open_verified(root / "simulated.fits")[0]
    if sim.header.get("ROWORDER") != "TOP-DOWN" or sim.header.get("SATURATE") != 16383:
        fail(f"simulated: ROWORDER {sim.header.get('ROWORDER')!r} SATURATE {sim.header.get('SATURATE')!r}")
    print(f"simulated.fits: ROWORDER={sim.header['ROWORDER']} SATURATE={sim.header['SATURATE']}")
    print("all checks passed")


if __name__ == "__main__":
    main()
