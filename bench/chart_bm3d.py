#!/usr/bin/env python3
"""VST + BM3D on a dark capture, written as a DNG a photographer's raw converter opens beside
pgrf's restorations (issue 51's chart measure: `bench/chart_look.py` compares the renders).

    pgrf enhance CAPTURE.dng --ratio R --model builtin:spc -o spc.dng
    pgrf convert spc.dng --uncompressed -o template.dng
    python3 bench/chart_bm3d.py CAPTURE.dng template.dng bm3d.dng --ratio R --noise-profile S O

BM3D gets what the networks get from `pgrf enhance` uncalibrated: the capture as LibRaw reads it
(`raw_image_visible`, unclamped), LibRaw's per-channel black (for a DNG with MaskedAreas, the masked
pixels' mean, which is what pgrf subtracts), the exposure ratio, and the DNG NoiseProfile (S, O: the
variance of a pixel at level x in [0, 1] of white - black is S x + O, as `pgrf info` prints it).
Amplified by R, the capture's variance is R S y + R^2 O, which is `bench/vst_bm3d.py`'s model with
alpha = R S and sigma = R sqrt(O); its generalised Anscombe transform, BM3D and exact unbiased
inverse restore each CFA plane.

The result is written into a copy of TEMPLATE (an uncompressed pgrf output of the same frame, so
the DNG carries exactly the metadata, black and white levels a pgrf restoration carries) at the
template's own black and white: DN = black_c + x (white - black_c), rounded. The copy is read back
with LibRaw and compared with what was written (exact, or the script fails); written atomically.
"""
import argparse
import os
import shutil
import sys

import numpy as np
import rawpy
import tifffile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from vst_bm3d import restore  # noqa: E402


def planes(raw, colors):
    """The mosaic's four CFA sites (2 x 2 offsets, row-major) as packed planes, and their colours."""
    sites = [(0, 0), (0, 1), (1, 0), (1, 1)]
    return [raw[r::2, c::2] for r, c in sites], [int(colors[r, c]) for r, c in sites], sites


def raw_ifd(path):
    """The CFA page of an uncompressed DNG: size, strip offsets and byte counts (read from the tags
    themselves), and its black (per CFA site) and white levels."""
    with tifffile.TiffFile(path) as t:
        for p in t.pages:
            if p.photometric == 32803:
                if p.compression != 1 or p.dtype != np.uint16:
                    sys.exit(f"{path}: the CFA image is not uncompressed 16-bit (pgrf convert --uncompressed)")
                black = np.reshape(np.array(p.tags["BlackLevel"].value, dtype=np.float64), (-1, 2))
                levels = (black[:, 0] / black[:, 1], float(p.tags["WhiteLevel"].value))
                strips = [np.atleast_1d(p.tags[k].value).tolist() for k in ("StripOffsets", "StripByteCounts")]
                return p.shape, strips[0], strips[1], levels
    sys.exit(f"{path}: no CFA image")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("capture")
    ap.add_argument("template")
    ap.add_argument("output")
    ap.add_argument("--ratio", type=float, required=True)
    ap.add_argument("--noise-profile", type=float, nargs=2, required=True, metavar=("S", "O"))
    a = ap.parse_args()
    if os.path.abspath(a.output) in (os.path.abspath(a.capture), os.path.abspath(a.template)):
        sys.exit("the output must not be an input")
    with rawpy.imread(a.capture) as r:
        raw = r.raw_image_visible.astype(np.float64)
        colors = r.raw_colors_visible.copy()
        black = np.array(r.black_level_per_channel, dtype=np.float64)
        white = float(r.white_level)
    shape, offsets, counts, (out_black, out_white) = raw_ifd(a.template)
    if tuple(shape) != raw.shape:
        sys.exit(f"template {shape} and capture {raw.shape} differ in size")
    ps, cs, sites = planes(raw, colors)
    capture = np.stack([(p - black[c]) / (white - black[c]) * a.ratio for p, c in zip(ps, cs)])
    s, o = a.noise_profile
    noise = {"alpha": a.ratio * s, "sigma": a.ratio * np.sqrt(o), "offset": [0.0] * 4}
    x = restore(capture.astype(np.float32), noise)
    mosaic = np.empty(raw.shape, dtype=np.uint16)
    for i, (rr, cc) in enumerate(sites):
        # The template's BlackLevel is per CFA site in the 2 x 2 repeat pattern (row-major).
        b = out_black[i % len(out_black)]
        mosaic[rr::2, cc::2] = np.clip(np.rint(b + x[i] * (out_white - b)), 0, 65535).astype(np.uint16)
    tmp = a.output + ".part"
    shutil.copyfile(a.template, tmp)
    flat = mosaic.astype("<u2").tobytes()
    if sum(counts) != len(flat):
        sys.exit(f"template strips hold {sum(counts)} bytes, the frame {len(flat)}")
    with open(tmp, "r+b") as f:
        at = 0
        for off, n in zip(offsets, counts):
            f.seek(off)
            f.write(flat[at : at + n])
            at += n
    with rawpy.imread(tmp) as r:
        back = r.raw_image_visible
        if not np.array_equal(back, mosaic):
            os.remove(tmp)
            sys.exit("LibRaw reads back other pixels than were written")
    os.replace(tmp, a.output)
    print(f"wrote {a.output}: mean restored level {x.mean():.5f} of white (capture {capture.mean():.5f})")


if __name__ == "__main__":
    main()
