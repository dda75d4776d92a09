#!/usr/bin/env python3
"""How far each restoration sits above the reference in the dark areas of a
`pgrf demo` folder (MODELS.md, "The calibrated measure": PGRF's lifted black).

    python3 bench/dark_bias.py DEMO_DIR [--dark 0.01] [--offset-dn 2.43]

Reads DEMO_DIR/clean.dng and the restorations {spc,pgrf}_x{100,200}.dng
(tifffile + imagecodecs for the lossless-JPEG DNGs pgrf writes), packs each
into R, G1, B, G2 normalised by the file's black and white levels, and takes
the packed pixels whose reference green, (G1 + G2) / 2, is below --dark of
white. Prints per channel the reference's mean there and each file's mean
minus the reference's. The noisy captures (noisy_x*.dng, the dark frame
before amplification, carrying the camera's dark-level offset) are shown as
the models get them: amplified by the ratio, less --offset-dn x ratio / 15871
(the A7S2's black-level error at ISO 1600 on its 14-bit range, which the demo
subtracts), clamped to [0, 1].
"""

import argparse
import os

import numpy as np
import tifffile

A7S2_RANGE_DN = 15871.0


def packed(path):
    page = tifffile.TiffFile(path).pages[0]
    raw = page.asarray().astype(np.float64)
    black = float(np.ravel(page.tags["BlackLevel"].value)[0])
    white = float(np.ravel(page.tags["WhiteLevel"].value)[0])
    planes = [raw[0::2, 0::2], raw[0::2, 1::2], raw[1::2, 1::2], raw[1::2, 0::2]]
    return (np.stack(planes) - black) / (white - black)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("demo_dir")
    ap.add_argument("--dark", type=float, default=0.01)
    ap.add_argument("--offset-dn", type=float, default=2.43)
    a = ap.parse_args()
    ref = packed(os.path.join(a.demo_dir, "clean.dng"))
    mask = (ref[1] + ref[3]) / 2 < a.dark
    fmt = lambda v: " ".join("%+.4f" % x for x in v)
    print("dark pixels: %.1f %% of the frame (reference green < %g)" % (100 * mask.mean(), a.dark))
    print("reference mean R G1 B G2: " + " ".join("%.4f" % ref[c][mask].mean() for c in range(4)))
    for ratio in (100, 200):
        noisy = packed(os.path.join(a.demo_dir, "noisy_x%d.dng" % ratio))
        noisy = np.clip(noisy * ratio - a.offset_dn * ratio / A7S2_RANGE_DN, 0, 1)
        print("x%d noisy input - reference: %s" % (ratio, fmt([(noisy[c] - ref[c])[mask].mean() for c in range(4)])))
        for name in ("spc", "pgrf"):
            out = packed(os.path.join(a.demo_dir, "%s_x%d.dng" % (name, ratio)))
            print("x%d %-4s - reference:        %s" % (ratio, name, fmt([(out[c] - ref[c])[mask].mean() for c in range(4)])))


if __name__ == "__main__":
    main()
