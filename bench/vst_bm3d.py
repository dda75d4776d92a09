#!/usr/bin/env python3
"""The classical peer of pgrf's models: generalised Anscombe VST + BM3D on the
packed raw planes, with the true noise parameters of each synthetic capture.

    pgrf eval --protocol synthetic --root REALSET --iso 1600,3200,6400 --ratio 100,200 \
        --dump DUMP ...
    python3 bench/vst_bm3d.py DUMP OUT
    pgrf eval --protocol synthetic --root REALSET --iso 1600,3200,6400 --ratio 100,200 \
        --model builtin:spc --model builtin:pgrf --outputs vst-bm3d=OUT ...

For every KEY.json that `pgrf eval --dump` wrote beside KEY.capture.npy (the
amplified capture y before clamping, packed R, G1, B, G2, normalised to the
reference's levels), this writes OUT/KEY.output.npy, which `pgrf eval
--outputs` measures exactly as it measures pgrf's models.

Per plane c, with the record's Poisson-Gaussian approximation of the capture,
E[y] = x + offset_c and Var[y] = alpha * x + sigma^2 (alpha = ratio * K / range;
sigma^2 = ratio^2 (read^2 + row^2 + 1/12) / range^2):

1. z = (y - offset_c) / alpha, s = sigma / alpha (Poisson units);
2. generalised Anscombe transform f = 2 sqrt(max(z + 3/8 + s^2, 0)), whose
   noise is close to N(0, 1) (Makitalo and Foi 2013);
3. BM3D (PyPI `bm3d`, Foi's group; profile 'np', both stages) with sigma_psd 1;
4. Makitalo and Foi's closed-form approximation of the exact unbiased inverse
   I(D) = D^2/4 + sqrt(3/2)/4 D^-1 - 11/8 D^-2 + 5 sqrt(3/2)/8 D^-3 - 1/8 - s^2,
   floored at 0, times alpha.

Row noise is counted in the variance but treated as white (it is a per-row
offset): what BM3D's white-noise model can take. `--jobs N` runs N cases at
once. Prints one line per case and the seconds it took.
"""

import argparse
import json
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import bm3d
import numpy as np


def gat(z, s):
    return 2.0 * np.sqrt(np.maximum(z + 0.375 + s * s, 0.0))


def inverse_gat(d, s):
    d = np.maximum(d, 1e-3)
    r = math.sqrt(1.5)
    x = 0.25 * d**2 + 0.25 * r / d - 11.0 / 8.0 / d**2 + 0.625 * r / d**3 - 0.125 - s * s
    return np.maximum(x, 0.0)


def restore(capture, noise):
    alpha, sigma = float(noise["alpha"]), float(noise["sigma"])
    offsets = noise["offset"]
    s = sigma / alpha
    out = np.empty_like(capture, dtype=np.float32)
    for c in range(capture.shape[0]):
        z = (capture[c].astype(np.float64) - float(offsets[c])) / alpha
        d = bm3d.bm3d(gat(z, s), sigma_psd=1.0)
        out[c] = (alpha * inverse_gat(np.asarray(d, dtype=np.float64), s)).astype(np.float32)
    return out


def one(args):
    dump, out, key = args
    t = time.time()
    with open(os.path.join(dump, key + ".json")) as f:
        meta = json.load(f)
    if "noise" not in meta:
        raise SystemExit(f"{key}.json has no noise record: dump a synthetic evaluation")
    capture = np.load(os.path.join(dump, key + ".capture.npy"))
    result = restore(capture, meta["noise"])
    tmp = os.path.join(out, key + ".output.npy.part")
    with open(tmp, "wb") as f:
        np.save(f, result)
    os.replace(tmp, os.path.join(out, key + ".output.npy"))
    return key, time.time() - t


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dump", help="folder written by pgrf eval --dump")
    ap.add_argument("out", help="folder for KEY.output.npy (created)")
    ap.add_argument("--jobs", type=int, default=1, help="cases at once")
    ap.add_argument(
        "--resume",
        action="store_true",
        help="skip cases whose KEY.output.npy exists (outputs are written atomically, so one "
        "that exists is whole): continue a run that was stopped",
    )
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    keys = sorted(f[: -len(".json")] for f in os.listdir(a.dump) if f.endswith(".json"))
    if not keys:
        sys.exit(f"{a.dump}: no KEY.json files (run pgrf eval --dump first)")
    if a.resume:
        done = [k for k in keys if os.path.exists(os.path.join(a.out, k + ".output.npy"))]
        if done:
            print(f"{len(done)} cases already restored in {a.out}, skipped", flush=True)
        keys = [k for k in keys if k not in set(done)]
    t0 = time.time()
    with ProcessPoolExecutor(max_workers=max(1, a.jobs)) as pool:
        for key, secs in pool.map(one, [(a.dump, a.out, k) for k in keys]):
            print(f"{key}: {secs:.1f} s", flush=True)
    print(f"{len(keys)} cases in {time.time() - t0:.1f} s (bm3d {bm3d.__version__ if hasattr(bm3d, '__version__') else '4.x'})")


if __name__ == "__main__":
    main()
