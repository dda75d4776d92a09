#!/usr/bin/env python3
"""Peer benchmark for `pgrf-bench decode`: LibRaw (via rawpy) decode + pack to
4 planes (R, G1, B, G2) + per-channel normalisation, the same work pgrf times.

Prints one JSON line per file with median/min milliseconds over --iters runs
after one warm-up, in the same shape as `pgrf-bench decode --json`.
"""
import argparse
import json
import statistics
import time

import numpy as np
import rawpy


def decode_pack(path):
    with rawpy.imread(path) as raw:
        # rawpy unpacks lazily, on first access to the raw arrays: that access
        # is the decode.
        visible = raw.raw_image_visible
        t1 = time.perf_counter()
        mosaic = visible.astype(np.float32)
        pattern = raw.raw_pattern  # colour index per 2x2 position, 0 R 1 G 2 B 3 G2
        black = np.array(raw.black_level_per_channel, dtype=np.float32)
        white = float(raw.white_level)
        h, w = mosaic.shape[0] // 2 * 2, mosaic.shape[1] // 2 * 2
        planes = [None] * 4
        for dy in range(2):
            for dx in range(2):
                c = int(pattern[dy, dx])
                planes[c] = (mosaic[dy:h:2, dx:w:2] - black[c]) / (white - black[c])
        out = np.clip(np.stack(planes), 0.0, 1.0)
        return t1, out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("files", nargs="+")
    ap.add_argument("--iters", type=int, default=20)
    a = ap.parse_args()
    for f in a.files:
        decode_pack(f)  # warm-up
        dec, pack, tot = [], [], []
        for _ in range(a.iters):
            t0 = time.perf_counter()
            t1, out = decode_pack(f)
            t2 = time.perf_counter()
            dec.append((t1 - t0) * 1e3)
            pack.append((t2 - t1) * 1e3)
            tot.append((t2 - t0) * 1e3)
        print(json.dumps({
            "file": f,
            "megapixels": out.shape[1] * out.shape[2] * 4 / 1e6,
            "iters": a.iters,
            "decode_ms_median": statistics.median(dec),
            "pack_ms_median": statistics.median(pack),
            "total_ms_median": statistics.median(tot),
            "total_ms_min": min(tot),
            "rawpy": rawpy.__version__,
            "libraw": ".".join(map(str, rawpy.libraw_version)),
        }))


if __name__ == "__main__":
    main()
