#!/usr/bin/env python3
"""Peer benchmark for `pgrf-bench stack`: the straightforward numpy way to get
per-pixel mean and variance of a bias stack: decode every DNG with rawpy
(LibRaw), stack the visible mosaics into one (N, H, W) array, np.mean and
np.var over the frame axis (float64). Prints one JSON line with wall time and
the process's peak resident memory.
"""
import argparse
import json
import os
import resource
import time

import numpy as np
import rawpy


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dir")
    a = ap.parse_args()
    files = sorted(os.path.join(a.dir, f) for f in os.listdir(a.dir) if not f.startswith("."))
    t0 = time.perf_counter()
    frames = []
    for f in files:
        with rawpy.imread(f) as raw:
            frames.append(raw.raw_image_visible.copy())
    t1 = time.perf_counter()
    stack = np.stack(frames)
    del frames
    mean = stack.mean(axis=0, dtype=np.float64)
    var = stack.var(axis=0, dtype=np.float64, ddof=1)
    t2 = time.perf_counter()
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(json.dumps({
        "frames": len(files),
        "total_s": t2 - t0,
        "decode_s": t1 - t0,
        "peak_rss_mib": peak,
        "mean_of_var": float(var.mean()),
        "mean_of_mean": float(mean.mean()),
    }))


if __name__ == "__main__":
    main()
