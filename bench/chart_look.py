#!/usr/bin/env python3
"""The 550D chart as a photographer sees it (issue 51's measure): each DNG rendered by
darktable-cli (Debian's darktable, default processing, a throw-away config and an in-memory
library) and, with --rawtherapee, by rawtherapee-cli (its default profile), then compared with
the reference rendered the same way:

- CIEDE2000 between each of the 24 ColorChecker patches' mean CIELAB and the reference's (a
  box of 41 x 41 pixels at each patch centre), mean and worst;
- the chart's black surround (the strip below the patches): CIEDE2000 and the mean sRGB
  difference in 8-bit units (a lifted, magenta black shows as + R, + B);
- a picture of a 100 % crop (the darkest patches and the surround) of every render side by side.

Usage: bench/chart_look.py OUT REFERENCE.dng NAME=FILE.dng ... [--rawtherapee]
Writes OUT/NAME.<renderer>.png, OUT/look.<renderer>.png (crops side by side) and prints one table
per renderer (Markdown). Needs numpy, Pillow and scikit-image (pip).
"""
import argparse
import os
import shutil
import subprocess
import sys
import tempfile

import numpy as np
from PIL import Image, ImageDraw
from skimage.color import deltaE_ciede2000, rgb2lab

# Patch centres in the built-in 550D chart (canon550d_colorchart.dng, 1734 x 1156 as rendered):
# columns 712 + 108 i, rows 622 + 101 j (row 0 brown .. cyan, row 3 white .. black).
COLS = [712 + 108 * i for i in range(6)]
ROWS = [622 + 101 * j for j in range(4)]
HALF = 20
# The chart's black body below the patches, and the 100 % crop (left, top, right, bottom).
SURROUND = (720, 985, 1240, 1000)
CROP = (980, 830, 1340, 1060)


def render(renderer, dng, png, work):
    if renderer == "darktable":
        conf = os.path.join(work, "dtconf")
        cmd = ["darktable-cli", dng, png, "--core", "--configdir", conf, "--library", ":memory:"]
    else:
        conf = os.path.join(work, "rtconf")
        # -d: the default processing profile; -n: PNG; -Y: overwrite.
        cmd = ["rawtherapee-cli", "-d", "-n", "-Y", "-o", png, "-c", dng]
        os.environ["HOME"] = conf
    if os.path.exists(png):
        os.remove(png)
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0 or not os.path.exists(png):
        sys.exit(f"chart_look: {renderer} failed on {dng}: {r.stderr.strip()[-400:]}")
    return np.asarray(Image.open(png).convert("RGB"), dtype=np.float64) / 255.0


def box_lab(img, cx, cy, half=HALF):
    return rgb2lab(img[cy - half : cy + half + 1, cx - half : cx + half + 1].reshape(1, -1, 3)).mean(
        axis=1
    )[0]


def region(img, box):
    l, t, r, b = box
    return img[t:b, l:r]


def measure(img, ref):
    de = []
    for y in ROWS:
        for x in COLS:
            de.append(float(deltaE_ciede2000(box_lab(ref, x, y), box_lab(img, x, y))))
    s_img, s_ref = region(img, SURROUND), region(ref, SURROUND)
    lab = lambda a: rgb2lab(a.reshape(1, -1, 3)).mean(axis=1)[0]
    black_de = float(deltaE_ciede2000(lab(s_ref), lab(s_img)))
    black_rgb = (s_img.reshape(-1, 3).mean(0) - s_ref.reshape(-1, 3).mean(0)) * 255.0
    return de, black_de, black_rgb


def side_by_side(crops, names, path):
    w = sum(c.width for c in crops) + 8 * (len(crops) - 1)
    h = crops[0].height + 18
    out = Image.new("RGB", (w, h), (255, 255, 255))
    d = ImageDraw.Draw(out)
    x = 0
    for c, n in zip(crops, names):
        out.paste(c, (x, 18))
        d.text((x + 2, 2), n, fill=(0, 0, 0))
        x += c.width + 8
    out.save(path)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out")
    ap.add_argument("reference")
    ap.add_argument("items", nargs="+", help="NAME=FILE.dng")
    ap.add_argument("--rawtherapee", action="store_true", help="also render with rawtherapee-cli")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    items = [i.split("=", 1) for i in a.items]
    renderers = ["darktable"] + (["rawtherapee"] if a.rawtherapee else [])
    work = tempfile.mkdtemp(prefix="chart_look")
    try:
        for rd in renderers:
            ref = render(rd, a.reference, os.path.join(a.out, f"reference.{rd}.png"), work)
            crops = [Image.fromarray((region(ref, CROP) * 255).round().astype(np.uint8))]
            names = ["reference"]
            print(f"\n{rd}: CIEDE2000 against the reference rendered the same way")
            print("| | patches mean | worst | black surround | black sRGB R / G / B (of 255) |")
            print("|---|---:|---:|---:|---|")
            for name, dng in items:
                img = render(rd, dng, os.path.join(a.out, f"{name}.{rd}.png"), work)
                if img.shape != ref.shape:
                    sys.exit(f"chart_look: {dng} renders {img.shape}, the reference {ref.shape}")
                de, bde, brgb = measure(img, ref)
                print(
                    f"| {name} | {np.mean(de):.2f} | {np.max(de):.2f} | {bde:.2f} | "
                    f"{brgb[0]:+.1f} / {brgb[1]:+.1f} / {brgb[2]:+.1f} |"
                )
                crops.append(Image.fromarray((region(img, CROP) * 255).round().astype(np.uint8)))
                names.append(name)
            side_by_side(crops, names, os.path.join(a.out, f"look.{rd}.png"))
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
