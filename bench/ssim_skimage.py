#!/usr/bin/env python3
"""Peer benchmark for `pgrf-bench ssim`: scikit-image's PSNR + SSIM under the
ELD protocol on the same A7S2-sized packed pair (4 x 1424 x 2128), built from
the same formula as crates/bench/src/ssim.rs (identical float32 values),
so the scores can be compared as well as the times.

ELD's evaluation: output clamped to [0, 1], least-squares gain over reference
pixels != 1, x255 as float32 and clipped, HWC layout, then
peak_signal_noise_ratio(data_range=255) and
structural_similarity(data_range=255, channel_axis=-1).

Timed variants (median over --iters after one warm-up):
  metrics_f64 : the two scikit-image calls on float64 HWC images (the numbers
                pgrf reproduces to 1e-6)
  full_f64    : the whole protocol from the packed float32 pair (clamp, gain,
                x255, transpose, float64) plus the two calls
  metrics_f32 : the two calls on float32 HWC images (what ELD literally runs;
                scikit-image then computes SSIM in float32)
Prints one JSON line.
"""
import argparse
import json
import statistics
import time

import numpy as np
import scipy
import skimage
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

SHAPE = (4, 1424, 2128)
SEED = 7


def splitmix64(k):
    with np.errstate(over="ignore"):
        z = k + np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return z ^ (z >> np.uint64(31))


def pair():
    c, h, w = SHAPE
    ci = np.arange(c)[:, None, None]
    ii = np.arange(h)[None, :, None]
    jj = np.arange(w)[None, None, :]
    tri = np.abs((ii + 2 * jj + 16 * ci) % 512 - 256)
    num = 4 * tri + (7 * ii + 3 * jj) % 41
    ref = num.astype(np.float32) / np.float32(1100.0)
    k = np.arange(c * h * w, dtype=np.uint64) + np.uint64(SEED)
    u = (splitmix64(k) >> np.uint64(40)).astype(np.float32) / np.float32(16777216.0)
    out = np.float32(0.9) * ref + (u.reshape(SHAPE) - np.float32(0.5)) * np.float32(0.05)
    assert out.dtype == np.float32 and ref.dtype == np.float32
    return out, ref


def prepare(out, ref, correct, dtype):
    o = np.clip(out, np.float32(0), np.float32(1))
    gain = None
    if correct:
        m = ref != np.float32(1)
        o64, r64 = o[m].astype(np.float64), ref[m].astype(np.float64)
        gain = float(np.dot(o64, r64) / np.dot(o64, o64))
        o = np.float32(gain) * o
    O = np.clip(o * np.float32(255), np.float32(0), np.float32(255))
    R = np.clip(ref * np.float32(255), np.float32(0), np.float32(255))
    O = np.transpose(O, (1, 2, 0)).astype(dtype)
    R = np.transpose(R, (1, 2, 0)).astype(dtype)
    return O, R, gain


def metrics(O, R):
    p = peak_signal_noise_ratio(R, O, data_range=255)
    s = structural_similarity(R, O, data_range=255, channel_axis=-1)
    return float(p), float(s)


def timed(fn, iters):
    fn()
    ms = []
    for _ in range(iters):
        t = time.perf_counter()
        fn()
        ms.append((time.perf_counter() - t) * 1e3)
    return statistics.median(ms), min(ms)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--iters", type=int, default=3)
    a = ap.parse_args()
    out, ref = pair()
    O, R, gain = prepare(out, ref, True, np.float64)
    psnr, ssim = metrics(O, R)
    O32, R32, _ = prepare(out, ref, True, np.float32)
    psnr32, ssim32 = metrics(O32, R32)
    m64, m64_min = timed(lambda: metrics(O, R), a.iters)
    full, _ = timed(lambda: metrics(*prepare(out, ref, True, np.float64)[:2]), a.iters)
    m32, _ = timed(lambda: metrics(O32, R32), a.iters)
    print(json.dumps(dict(
        shape=list(SHAPE), iters=a.iters,
        metrics_f64_ms_median=m64, metrics_f64_ms_min=m64_min,
        full_f64_ms_median=full, metrics_f32_ms_median=m32,
        psnr=psnr, ssim=ssim, gain=gain, psnr_f32=psnr32, ssim_f32=ssim32,
        numpy=np.__version__, scipy=scipy.__version__, skimage=skimage.__version__,
    )))


if __name__ == "__main__":
    main()
