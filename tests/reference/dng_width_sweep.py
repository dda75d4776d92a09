#!/usr/bin/env python3
"""LibRaw reads every DNG pgrf writes exactly: a sweep over frame sizes.

    pip install rawpy numpy
    python3 tests/reference/dng_width_sweep.py [--pgrf target/debug/pgrf]
        [--quick] [--work DIR]

For each size (widths and heights around pgrf's 256-pixel LJPEG tiles:
exact multiples of the tile, 512 = two tiles, odd remainders, frames
narrower than one tile, frames narrower than 16 pixels) it writes a
seeded random 14-bit mosaic as a headerless dump, has `pgrf convert`
turn it into a DNG (lossless LJPEG-92 tiles, the default, and, for a
few sizes, `--uncompressed` strips and a monochrome LinearRaw frame),
then compares

  - rawpy's (LibRaw's) raw_image with the mosaic that went in, and
  - pgrf's own decode of the DNG (`pgrf convert x.dng -o x.fits`, a
    16-bit FITS read here) with the same mosaic,

pixel for pixel. A size passes when both are equal everywhere. The
table gives, per size, the number of pixels LibRaw got wrong and the
tile width the DNG records (TileWidth, read from its IFD).

Why: LibRaw's lossless_dng_load_raw (0.22) has a special case for
LJPEG data of two or more components: when `clrs * jwide == raw_width`
(jwide being the tile's JPEG row in pixels, here the tile width) it
reads twice as many pixels per JPEG row as there are. pgrf's tiles are
two-component LJPEG of the tile width, so a frame exactly two tiles
wide (512 with tiles of 256) was read with every row wrong. Its tile
loop also ends a row at the image width (`col >= raw_width`), so a tile
wider than the whole image shifts every row. pgrf's writer therefore
picks the tile width per frame (`pgrf_raw::tile_width`): never wider
than the frame and never exactly half of it (frames under 16 pixels
keep one 16-pixel tile: LibRaw opens no frame under 22 pixels a side,
whatever its layout, and such sizes are reported as "too small").

Run on 2026-11-27 with LibRaw 0.22.2 (rawpy 0.28.0, numpy 2), full sweep:

    before (tiles of 256 at every size): 238 sizes, 61 wrong in LibRaw
      (every width from 22 to 255, and 512, at every height of 22 or
      more: e.g. 512x64 32256 of 32768 pixels wrong, 200x40 7800 of 8000,
      100x30 mono 2899 of 3000), 88 exact, 89 too small for LibRaw;
      pgrf's own decode exact at every size
    after (`tile_width`): 246 sizes (6000 wide added), 0 wrong, 155
      exact in LibRaw and in pgrf, 91 too small for LibRaw

crates/raw/tests/dng_layout.rs holds the rule without Python: it reads
each tile's SOF3 back from the file and steps through it as LibRaw's
loop does.
"""

import argparse
import struct
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import rawpy

QUICK = [
    (512, 64), (512, 512), (256, 192), (768, 64), (1024, 64),
    (200, 40), (128, 32), (100, 30), (16, 16), (8, 6),
]
WIDTHS = [8, 10, 14, 16, 18, 30, 32, 34, 64, 100, 128, 200, 240, 254, 256, 258,
          300, 384, 496, 510, 512, 514, 528, 640, 768, 1000, 1024, 1536, 1888, 6000]
HEIGHTS = [6, 16, 64, 255, 256, 257, 300, 512]


def fits_pixels(path, w, h):
    """The 16-bit image of a FITS pgrf wrote (BITPIX 16, BZERO 32768)."""
    b = Path(path).read_bytes()
    cards, at = {}, 0
    while True:
        block = b[at : at + 2880]
        at += 2880
        done = False
        for i in range(36):
            card = block[80 * i : 80 * i + 80].decode("ascii")
            key = card[:8].strip()
            if key == "END":
                done = True
                break
            if card[8:10] == "= ":
                cards[key] = card[10:].split("/")[0].strip()
        if done:
            break
    assert int(cards["BITPIX"]) == 16, cards
    assert (int(cards["NAXIS1"]), int(cards["NAXIS2"])) == (w, h), cards
    zero = float(cards.get("BZERO", "0"))
    data = np.frombuffer(b[at : at + 2 * w * h], dtype=">i2").astype(np.int64)
    img = (data + int(zero)).reshape(h, w)
    flip = cards.get("ROWORDER", "'TOP-DOWN'").strip("' ") == "BOTTOM-UP"
    return img[::-1] if flip else img


def tile_width(dng):
    """TileWidth of the first IFD that has one (None: strips)."""
    b = Path(dng).read_bytes()
    e = "<" if b[:2] == b"II" else ">"
    todo, seen = [struct.unpack(e + "I", b[4:8])[0]], set()
    while todo:
        off = todo.pop()
        if off in seen or off == 0 or off + 2 > len(b):
            continue
        seen.add(off)
        n = struct.unpack(e + "H", b[off : off + 2])[0]
        for i in range(n):
            at = off + 2 + 12 * i
            tag, typ, count = struct.unpack(e + "HHI", b[at : at + 8])
            if tag == 322:
                return struct.unpack(e + ("H" if typ == 3 else "I"), b[at + 8 : at + (10 if typ == 3 else 12)])[0]
            if tag == 330:
                v = struct.unpack(e + "I", b[at + 8 : at + 12])[0]
                todo += [v] if count == 1 else [struct.unpack(e + "I", b[v + 4 * k : v + 4 * k + 4])[0] for k in range(count)]
        todo.append(struct.unpack(e + "I", b[off + 2 + 12 * n : off + 6 + 12 * n])[0])
    return None


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    root = Path(__file__).resolve().parent.parent.parent
    ap.add_argument("--pgrf", default=str(root / "target/debug/pgrf"))
    ap.add_argument("--quick", action="store_true", help="ten sizes instead of the full sweep")
    ap.add_argument("--work", default=None)
    a = ap.parse_args()
    work = Path(a.work or tempfile.mkdtemp(prefix="pgrf-dng-sweep-"))
    work.mkdir(parents=True, exist_ok=True)
    print(f"LibRaw {'.'.join(map(str, rawpy.libraw_version))}, rawpy {rawpy.__version__}")
    cases = [(w, h, "RGGB", ()) for (w, h) in QUICK] if a.quick else \
        [(w, h, "RGGB", ()) for w in WIDTHS for h in HEIGHTS]
    cases += [(w, h, "mono", ()) for (w, h) in [(512, 64), (256, 64), (100, 30)]]
    cases += [(w, h, "RGGB", ("--uncompressed",)) for (w, h) in [(512, 64), (100, 30), (8, 6)]]
    failed = []
    print(f"{'size':>11} {'cfa':>5} {'storage':>13} {'tile':>5} {'LibRaw wrong':>13} {'pgrf wrong':>11}")
    for w, h, cfa, extra in cases:
        rng = np.random.default_rng(w * 1009 + h)
        mosaic = rng.integers(600, 16000, size=(h, w), dtype=np.uint16)
        dump = work / f"in_{w}x{h}.raw"
        mosaic.astype("<u2").tofile(dump)
        dng = work / f"s_{w}x{h}.dng"
        subprocess.run(
            [a.pgrf, "convert", str(dump), "--width", str(w), "--height", str(h), "--bits", "14",
             "--cfa", cfa, "--black", "512", "--white", "16383", "-o", str(dng), *extra],
            check=True, stderr=subprocess.DEVNULL,
        )
        tw = tile_width(dng)
        fits = work / "back.fits"
        subprocess.run([a.pgrf, "convert", str(dng), "-o", str(fits)], check=True, stderr=subprocess.DEVNULL)
        own = int((fits_pixels(fits, w, h) != mosaic).sum())
        try:
            with rawpy.imread(str(dng)) as r:
                got = r.raw_image.copy()
            libraw = int((got != mosaic).sum()) if got.shape == mosaic.shape else w * h
        except rawpy.LibRawError as e:
            # LibRaw opens no raw under 22 pixels a side (identify():
            # "height < 22 || width < 22"): not a layout question.
            libraw = "too small" if min(w, h) < 22 else f"refused ({type(e).__name__})"
        for p in (dump, dng, fits):
            p.unlink(missing_ok=True)
        storage = "uncompressed" if extra else ("LJ92 tiles" if tw else "strips")
        mark = "" if libraw in (0, "too small") and own == 0 else "  FAIL"
        print(f"{w:>5}x{h:<5} {cfa:>5} {storage:>13} {tw or '-':>5} {libraw:>13} {own:>11}{mark}", flush=True)
        if mark:
            failed.append((w, h, cfa, storage, libraw, own))
    print(f"{len(cases)} sizes, {len(failed)} failed" + ("" if not failed else ": " + ", ".join(
        f"{w}x{h} {cfa} {s} ({l} of {w * h} pixels wrong in LibRaw, {o} in pgrf)" for w, h, cfa, s, l, o in failed)))
    if not a.work:
        for p in work.iterdir():
            p.unlink()
        work.rmdir()
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
