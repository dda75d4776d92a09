#!/usr/bin/env python3
"""Peer benchmark for `pgrf-bench enhance`: the same whole-frame inference in
PyTorch, with the networks of bench/train_torch.py (imported, not copied).

Same input frame (the formula of crates/bench/src/enhance.rs, in
numpy), same tiling as pgrf_nn::infer (tile rounded down to the network's side
multiple unless the frame fits, then shrunk per axis to the smallest multiple
that covers the axis with as many tiles; tiles overlapping by at least
`overlap`, stride tile - overlap, the last tile flush with the end; an axis
that fits is not cut), the same raised-cosine blend weights, the same samplers:

- SID U-Net: one evaluation per tile.
- SR3 two-stage (the paper's): XZ = v(X0, T, 0) + X0, Xt2 = t2 XZ + (1 - t2) X0,
  out = v(Xt2, T, t2) + X0: two evaluations.
- one-step: X0 + v(X0, T, 0); euler:N: N Euler steps from t = 0 to 1.

X0 ~ N(0, I) is drawn once for the whole frame (torch generator, seed 0), so
tiles agree on it where they overlap, as in pgrf. Fresh weights (PyTorch's
default initialisation; timing does not depend on the values). Timed: the
whole restore (start noise, tiles, evaluations, blend, clamp) under
torch.inference_mode() with torch.set_num_threads(--threads). Prints one JSON
line; peak memory is the process's ru_maxrss.
"""
import argparse
import json
import os
import resource
import statistics
import sys
import time

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from train_torch import SidUnet, Sr3Unet  # noqa: E402

SEED = 11  # crates/bench/src/enhance.rs SEED
DEFAULT_OVERLAP = 64


# --------------------------------------------------------------------------
# Input frame (crates/bench/src/enhance.rs `frame`)
# --------------------------------------------------------------------------
def splitmix64(x):
    with np.errstate(over="ignore"):
        z = x + np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return z ^ (z >> np.uint64(31))


def frame(h, w):
    out = np.empty((4, h, w), np.float32)
    i = np.arange(h, dtype=np.int64).reshape(h, 1)
    j = np.arange(w, dtype=np.int64).reshape(1, w)
    for c in range(4):
        tri = np.abs((i + 2 * j + 16 * c) % 512 - 256)
        clean = (4 * tri + (7 * i + 3 * j) % 41).astype(np.float32) / np.float32(1100)
        key = (np.uint64(c) << np.uint64(42)) + (i.astype(np.uint64) << np.uint64(21)) + j.astype(np.uint64)
        u = (splitmix64(np.uint64(SEED) + key) >> np.uint64(40)).astype(np.float32) / np.float32(16777216)
        v = np.float32(0.8) * clean + (u - np.float32(0.5)) * np.float32(0.3)
        out[c] = np.clip(v, 0, 1)
    return out


# --------------------------------------------------------------------------
# Tiling (pgrf_nn::infer::tiles::AxisPlan, infer::image::plan_for)
# --------------------------------------------------------------------------
def axis_plan(total, tile, overlap):
    """(starts, len, weights per tile) along one axis."""
    if tile >= total:
        return [0], total, [np.ones(total, np.float32)]
    assert 0 < overlap and 2 * overlap <= tile, (tile, overlap)
    stride = tile - overlap
    starts, p = [], 0
    while p + tile < total:
        starts.append(p)
        p += stride
    starts.append(total - tile)
    margin = overlap // 4
    ramp = max(overlap - 2 * margin, 1)
    ramps = []
    for a, b in zip(starts, starts[1:]):
        region = a + tile - b
        ramps.append((b + (region - ramp) // 2, ramp))

    def up(jj, n):
        return 0.5 - 0.5 * np.cos(np.pi * (jj + 0.5) / n)

    weights = []
    for k, s in enumerate(starts):
        pos = s + np.arange(tile)
        wk = np.ones(tile, np.float64)
        if k > 0:
            r0, n = ramps[k - 1]
            wk *= np.where(pos < r0, 0.0, np.where(pos < r0 + n, up(pos - r0, n), 1.0))
        if k + 1 < len(starts):
            r0, n = ramps[k]
            wk *= np.where(pos < r0, 1.0, np.where(pos < r0 + n, 1.0 - up(pos - r0, n), 0.0))
        weights.append(wk.astype(np.float32))
    return starts, tile, weights


def plan_for(h, w, tile, overlap, multiple):
    """pgrf_nn::infer::image::plan_for: the tile rounded down to the
    network's multiple unless the frame fits, then shrunk per axis to the
    smallest multiple that covers the axis with as many tiles."""
    m = max(multiple, 1)
    if tile < max(h, w):
        tile = max(tile // m * m, m)

    def balanced(length):
        if tile >= length:
            return tile
        n = -(-(length - overlap) // (tile - overlap))
        even = -(-(-(-(length + (n - 1) * overlap) // n)) // m) * m
        return even if 2 * overlap <= even <= tile else tile

    return axis_plan(h, balanced(h), overlap), axis_plan(w, balanced(w), overlap), tile


# --------------------------------------------------------------------------
# Samplers (crates/nn/src/sample.rs)
# --------------------------------------------------------------------------
def velocity(net, x, cond, t):
    return net(x, cond, torch.full((x.shape[0],), t, dtype=torch.float32))


def sample(net, sampler, cond, x0, t2):
    if sampler == "two-stage":
        xz = velocity(net, x0, cond, 0.0) + x0
        xt2 = xz * t2 + x0 * (1.0 - t2)
        return velocity(net, xt2, cond, t2) + x0
    if sampler == "one-step":
        return velocity(net, x0, cond, 0.0) + x0
    steps = int(sampler.split(":")[1])
    dt = 1.0 / steps
    x = x0
    for i in range(steps):
        x = x + velocity(net, x, cond, i * dt) * dt
    return x


def nfe_of(net_kind, sampler):
    if net_kind == "unet":
        return 1
    if sampler == "two-stage":
        return 2
    if sampler == "one-step":
        return 1
    return int(sampler.split(":")[1])


def restore(net, net_kind, x, rows, cols, sampler, t2):
    c, h, w = x.shape
    xt = torch.from_numpy(x)
    x0 = None
    if net_kind == "sr3":
        x0 = torch.randn(1, c, h, w, generator=torch.Generator().manual_seed(0))
    acc = torch.zeros(c, h, w)
    (rs, rlen, rw), (cs, clen, cw) = rows, cols
    for a, y in enumerate(rs):
        for b, xx in enumerate(cs):
            cond = xt[:, y:y + rlen, xx:xx + clen].unsqueeze(0).contiguous()
            if net_kind == "unet":
                out = net(cond)
            else:
                x0t = x0[:, :, y:y + rlen, xx:xx + clen].contiguous()
                out = sample(net, sampler, cond, x0t, t2)
            wgt = torch.from_numpy(np.outer(rw[a], cw[b]))
            acc[:, y:y + rlen, xx:xx + clen] += out[0] * wgt
    return acc.clamp_(0.0, 1.0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--net", choices=["unet", "sr3"], default="unet")
    ap.add_argument("--width", type=int, default=32, help="SID U-Net width")
    ap.add_argument("--inner-channels", type=int, default=64)
    ap.add_argument("--channel-mults", default="1,2,4,8,8")
    ap.add_argument("--attn-levels", default="3", help='comma-separated or "none"')
    ap.add_argument("--frame", default="1424x2128", help="packed HxW or N")
    ap.add_argument("--tile", type=int, required=True)
    ap.add_argument("--overlap", type=int, default=DEFAULT_OVERLAP)
    ap.add_argument("--sampler", default="two-stage",
                    help="two-stage, one-step or euler:N")
    ap.add_argument("--t2", type=float, default=0.5)
    ap.add_argument("--iters", type=int, default=1)
    ap.add_argument("--warmup", type=int, default=0)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--expect-params", type=int, default=None,
                    help="pgrf's parameter count; checked")
    args = ap.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
        torch.set_num_interop_threads(1)
    torch.manual_seed(0)
    fh, _, fw = args.frame.lower().partition("x")
    h, w = int(fh), int(fw or fh)
    sampler = args.sampler.lower()
    assert sampler in ("two-stage", "one-step") or sampler.startswith("euler:"), sampler

    if args.net == "unet":
        net = SidUnet(args.width)
        multiple = 16
        cfg = {"width": args.width}
    else:
        mults = tuple(int(m) for m in args.channel_mults.split(","))
        attn = () if args.attn_levels.lower() in ("", "none") else tuple(
            int(a) for a in args.attn_levels.split(","))
        net = Sr3Unet(inner=args.inner_channels, mults=mults, attn_levels=attn)
        multiple = 1 << (len(mults) - 1)
        cfg = {"inner_channels": args.inner_channels, "channel_mults": list(mults),
               "attn_levels": list(attn)}
    net.eval()
    params = sum(p.numel() for p in net.parameters())

    t0 = time.perf_counter()
    x = frame(h, w)
    input_seconds = time.perf_counter() - t0
    rows, cols, tile = plan_for(h, w, args.tile, args.overlap, multiple)
    tiles = len(rows[0]) * len(cols[0])
    nfe = nfe_of(args.net, sampler)

    times, out = [], None
    with torch.inference_mode():
        for i in range(args.warmup + args.iters):
            t0 = time.perf_counter()
            out = restore(net, args.net, x, rows, cols, sampler, args.t2)
            s = time.perf_counter() - t0
            if i >= args.warmup:
                times.append(s)
            print(f"  torch run {i + 1}/{args.warmup + args.iters}: {s:.2f} s", file=sys.stderr)
    seconds = statistics.median(times)
    r = {
        "torch": torch.__version__,
        "threads": torch.get_num_threads(),
        "net": args.net,
        "config": cfg,
        "params": params,
        "frame": [4, h, w],
        "megapixels": 4 * h * w / 1e6,
        "tile": tile,
        "tile_hw": [rows[1], cols[1]],
        "tiles": tiles,
        "overlap": args.overlap,
        "sampler": "one pass" if args.net == "unet" else sampler,
        "nfe": nfe,
        "iters": args.iters,
        "warmup": args.warmup,
        "seconds": seconds,
        "seconds_min": min(times),
        "seconds_per_eval": seconds / nfe,
        "seconds_per_tile_eval": seconds / (nfe * tiles),
        "input_seconds": input_seconds,
        "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "output_mean": float(out.double().mean()),
    }
    print(json.dumps(r))
    if args.expect_params is not None and params != args.expect_params:
        print(f"PyTorch has {params} parameters, pgrf {args.expect_params}", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
