#!/usr/bin/env python3
"""Where PyTorch's training step spends its time, in the rows of `pgrf-bench train
--breakdown` (issue 55: the remaining gap, kernel by kernel).

    python3 bench/torch_breakdown.py --net unet --width 16 --batch 4 --size 128 --threads 1 [--steps 4]
    python3 bench/torch_breakdown.py --net sr3 --batch 2 --size 128 --threads 1

The networks are `bench/train_torch.py`'s (the same architectures as pgrf's, parameter
counts printed): the SID U-Net and the SR3 velocity field (its rectified-flow step, as
`pgrf-bench train` times it). After two warm-up steps, `--steps` training steps (forward,
L1 loss, backward, Adam) run under torch.profiler with shapes recorded; every operator's self CPU
time is put in one row by its name and its weight's shape, and in one phase by its
ancestors in the profile (under `Optimizer.step` or `zero_grad`: the optimiser; under the autograd
engine: backward; otherwise forward):

- conv 3x3, conv 1x1, conv transpose 2x2: `aten::mkldnn_convolution`,
  `aten::_convolution` and `aten::convolution_backward`, by the weight's kernel side
  and PyTorch's fallback `aten::_slow_conv2d_*` (the SR3's stride-2 convolutions are in
  conv 3x3);
- leaky relu, max pool 2x2, concatenation, group norm, silu: their forward and backward
  operators; attention core: the batched products and the softmax; linear: addmm / mm;
- other: everything else (the loss, gradient accumulation adds, copies, allocation,
  the profiler's own ranges).

Prints one Markdown table (ms per step) and one JSON line, with the step's wall time and
Adam's update timed without the profiler (whose cost per operator inflates the optimiser's
many small operations most).
"""
import argparse
import json
import os
import sys
import time

import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from train_torch import SidUnet, Sr3Unet  # noqa: E402

CONV = {
    "aten::mkldnn_convolution": 1,
    "aten::_convolution": 1,
    "aten::convolution_backward": 2,
    # PyTorch's fallback for the shapes oneDNN does not take (the SR3's smallest levels).
    "aten::_slow_conv2d_forward": 1,
    "aten::_slow_conv2d_backward": 2,
}
ROWS = {
    "aten::leaky_relu": "leaky relu",
    "aten::leaky_relu_backward": "leaky relu",
    "aten::max_pool2d_with_indices": "max pool 2x2",
    "aten::max_pool2d_with_indices_backward": "max pool 2x2",
    "aten::cat": "concatenation",
    "aten::native_group_norm": "group norm",
    "aten::native_group_norm_backward": "group norm",
    "aten::silu": "silu",
    "aten::silu_backward": "silu",
    "aten::bmm": "attention core",
    "aten::baddbmm": "attention core",
    "aten::_softmax": "attention core",
    "aten::_softmax_backward_data": "attention core",
    "aten::addmm": "linear",
    "aten::mm": "linear",
}


def row_of(event):
    """The breakdown row an operator's self time goes to."""
    if event.name in CONV:
        shapes = event.input_shapes or []
        i = CONV[event.name]
        if len(shapes) > i and len(shapes[i]) == 4:
            k = shapes[i][-1]
            return "conv transpose 2x2" if k == 2 else f"conv {k}x{k}"
        return "other"
    return ROWS.get(event.name, "other")


def phase_of(event):
    """forward, backward or optimiser, from the event and its ancestors."""
    if event.name.startswith("Optimizer."):
        return "optimiser"
    p = event.cpu_parent
    while p is not None:
        if p.name.startswith("Optimizer."):
            return "optimiser"
        if p.name.startswith("autograd::engine"):
            return "backward"
        p = p.cpu_parent
    return "backward" if event.name.startswith("autograd::engine") else "forward"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--net", choices=["unet", "sr3"], default="unet")
    ap.add_argument("--width", type=int, default=16, help="the U-Net's")
    ap.add_argument("--batch", type=int, default=4)
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--steps", type=int, default=4)
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    torch.set_num_interop_threads(1)
    torch.manual_seed(0)
    shape = (a.batch, 4, a.size, a.size)
    if a.net == "unet":
        net = SidUnet(a.width)
        x, y = torch.rand(shape), torch.rand(shape)

        def loss_fn():
            return (net(x) - y).abs().mean()
    else:
        net = Sr3Unet()
        cond, x1, x0 = torch.rand(shape), torch.rand(shape), torch.randn(shape)
        t = torch.rand(a.batch)
        t4 = t.reshape(a.batch, 1, 1, 1)

        def loss_fn():
            xt = x1 * t4 + x0 * (1 - t4)
            return ((x1 - x0) - net(xt, cond, t)).abs().mean()
    opt = torch.optim.Adam(net.parameters(), lr=1e-4, eps=1e-5)

    def step():
        opt.zero_grad(set_to_none=True)
        loss_fn().backward()
        t = time.perf_counter()
        opt.step()
        return time.perf_counter() - t

    for _ in range(2):
        step()
    t0 = time.perf_counter()
    adam = sum(step() for _ in range(a.steps)) * 1e3 / a.steps
    wall = (time.perf_counter() - t0) * 1e3 / a.steps
    from torch.profiler import ProfilerActivity, profile

    with profile(activities=[ProfilerActivity.CPU], record_shapes=True) as p:
        for _ in range(a.steps):
            step()
    table = {}
    for e in p.events():
        key = (row_of(e), phase_of(e))
        table[key] = table.get(key, 0.0) + e.self_cpu_time_total / 1e3 / a.steps
    rows = ["conv 3x3", "conv 1x1", "conv transpose 2x2", "leaky relu", "max pool 2x2", "concatenation",
            "group norm", "silu", "attention core", "linear", "other"]
    rows = [r for r in rows if r == "other" or (r, "forward") in table or (r, "backward") in table]
    name = f"SID U-Net width {a.width}" if a.net == "unet" else "SR3 velocity field"
    print(f"PyTorch {torch.__version__}, {a.threads} threads, {name}, "
          f"{sum(q.numel() for q in net.parameters())} params, batch {a.batch} x 4 x {a.size} x {a.size}; "
          f"step {wall:.1f} ms unprofiled (mean of {a.steps}), of which Adam's update {adam:.1f} ms")
    print("| row | forward ms | backward ms |")
    print("|---|---:|---:|")
    for r in rows:
        print(f"| {r} | {table.get((r, 'forward'), 0.0):.1f} | {table.get((r, 'backward'), 0.0):.1f} |")
    opt_ms = sum(v for (r, ph), v in table.items() if ph == "optimiser")
    print(f"| optimiser (profiled; {adam:.1f} ms unprofiled) | {opt_ms:.1f} | |")
    total = sum(table.values())
    print(f"| sum of self times | {total:.1f} | |")
    print(json.dumps({
        "torch": torch.__version__, "net": a.net, "threads": a.threads, "width": a.width, "batch": a.batch,
        "size": a.size, "step_ms": wall, "adam_ms": adam,
        "rows": {f"{r}/{ph}": round(v, 3) for (r, ph), v in sorted(table.items())},
    }))


if __name__ == "__main__":
    main()
