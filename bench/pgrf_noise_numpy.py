#!/usr/bin/env python3
"""Peer benchmark for `pgrf-bench synth`: the same PGRF composite noise model
written with numpy, on the same frame size (4 x 1424 x 2128 packed), with the
same kinds of per-pixel maps and the same constants (A7S2 at ISO 1600, ratio
100, exposure 0.1 s, sqrt dark law). numpy's Poisson sampler is also exact
(PTRS above mean 10), so the work matches.

Prints one JSON line: median/min ms per frame over --frames after one warm-up.
"""
import argparse
import json
import statistics
import time

import numpy as np

PH, PW = 1424, 2128
K = 9.563e-4 * 1600          # DN per electron
SIGMA_READ = 6.29925         # DN, PMN table at ISO 1600
SIGMA_ROW = 0.988786         # DN
DN_RANGE = 16383 - 512
BLACK = 512.0
RATIO = 100.0
EXPOSURE = 0.1


def setup(rng):
    # Clean content: a smooth scene covering the normalised range.
    y, x = np.mgrid[0:PH, 0:PW].astype(np.float32)
    base = 0.5 + 0.45 * np.sin(x / 97.0) * np.cos(y / 61.0)
    clean = np.stack([base * s for s in (0.6, 1.0, 0.7, 1.0)]).astype(np.float32)
    maps = {
        "bias": rng.standard_normal((4, PH, PW), dtype=np.float32),
        "sigma": (SIGMA_READ * np.exp(0.15 * rng.standard_normal((4, PH, PW), dtype=np.float32))).astype(np.float32),
        "dark": (2.0 * rng.random((4, PH, PW), dtype=np.float32)).astype(np.float32),
        "nfp": (0.05 * rng.standard_normal((4, PH, PW), dtype=np.float32)).astype(np.float32),
    }
    return clean, maps


def pgrf_noise(clean, maps, rng):
    s = clean * (DN_RANGE / RATIO)                                   # DN of the short exposure
    v = K * rng.poisson(s / K).astype(np.float32)                    # P
    dark_e = maps["dark"] * np.sqrt(EXPOSURE)                        # A (sqrt law)
    v += K * rng.poisson(dark_e).astype(np.float32) * (1.0 + maps["nfp"])  # A x F
    v += maps["bias"]                                                # F
    v += maps["sigma"] * rng.standard_normal(clean.shape, dtype=np.float32)  # G
    rows = SIGMA_ROW * rng.standard_normal(2 * PH, dtype=np.float32)   # H, one per sensor row
    v[0:2] += rows[0::2][None, :, None]
    v[2:4] += rows[1::2][None, :, None]
    v += rng.random(clean.shape, dtype=np.float32) - 0.5            # Q
    np.clip(v, -BLACK, DN_RANGE, out=v)
    return v * (RATIO / DN_RANGE)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=5)
    a = ap.parse_args()
    rng = np.random.default_rng(1)
    clean, maps = setup(rng)
    pgrf_noise(clean, maps, rng)  # warm-up
    times = []
    for _ in range(a.frames):
        t = time.perf_counter()
        out = pgrf_noise(clean, maps, rng)
        times.append((time.perf_counter() - t) * 1e3)
    print(json.dumps({
        "shape": list(out.shape),
        "frames": a.frames,
        "ms_median": statistics.median(times),
        "ms_min": min(times),
        "megapixels_per_s": out.size / 1e6 / (statistics.median(times) / 1e3),
        "numpy": np.__version__,
    }))


if __name__ == "__main__":
    main()
