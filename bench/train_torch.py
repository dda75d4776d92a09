#!/usr/bin/env python3
"""Peer benchmark for `pgrf-bench train`: the two pgrf networks re-implemented
in PyTorch, layer for layer as in crates/nn, timed the same way on the CPU.

- SID U-Net (crates/nn/src/unet.rs): five levels of two 3x3 convolutions
  (padding 1) with LeakyReLU(0.2) at widths w..16w, 2x2 max-pool down, 2x2
  stride-2 transposed convolution up, cat([up, skip]), a 1x1 head; 4 -> 4.
- SR3 velocity field (crates/nn/src/sr3.rs, default Sr3Config): 8 -> 4
  channels, inner 64, mults (1, 2, 4, 8, 8), two residual blocks per level,
  single-head self-attention at level 3 and in the first middle block,
  GroupNorm(32) + SiLU, 3x3 stride-2 convolutions down, nearest x2 + 3x3
  convolution up, sinusoidal t embedding -> Linear(64, 256) -> SiLU ->
  Linear(256, 64) added (through a per-block Linear) after each block's
  first convolution.

Timings: medians over --iters after --warmup runs, at batch N x 4 x S x S:
forward without autograd, and one training step (forward, L1 loss,
backward, Adam step), with torch.set_num_threads(--threads). The SR3 step
is pgrf's rectified-flow step: Xt = t X1 + (1 - t) X0, loss |X1 - X0 - v|.
Prints one JSON line (and, with --profile, torch.profiler tables on stderr).
"""
import argparse
import json
import math
import statistics
import sys
import time

import torch
import torch.nn as nn
import torch.nn.functional as F

# Parameter counts of the Rust networks at the default sizes (SidUnetConfig
# width 32, 4 -> 4; default Sr3Config), as `pgrf-bench train` prints them.
RUST_PARAMS = {"unet": 7_760_484, "sr3": 97_818_436}


# --------------------------------------------------------------------------
# SID U-Net
# --------------------------------------------------------------------------
class DoubleConv(nn.Module):
    def __init__(self, cin, cout):
        super().__init__()
        self.first = nn.Conv2d(cin, cout, 3, padding=1)
        self.second = nn.Conv2d(cout, cout, 3, padding=1)

    def forward(self, x):
        x = F.leaky_relu(self.first(x), 0.2)
        return F.leaky_relu(self.second(x), 0.2)


class SidUnet(nn.Module):
    def __init__(self, width=32, cin=4, cout=4):
        super().__init__()
        w = width
        widths = [w, 2 * w, 4 * w, 8 * w, 16 * w]
        self.down = nn.ModuleList()
        c = cin
        for ch in widths:
            self.down.append(DoubleConv(c, ch))
            c = ch
        self.up = nn.ModuleList()
        self.merge = nn.ModuleList()
        for level in reversed(range(4)):
            hi, lo = widths[level + 1], widths[level]
            self.up.append(nn.ConvTranspose2d(hi, lo, 2, stride=2))
            self.merge.append(DoubleConv(2 * lo, lo))
        self.head = nn.Conv2d(w, cout, 1)

    def forward(self, x):
        # pgrf's SidUnet::forward: sides padded up to a multiple of 16 by
        # reflection (zeros where too small to reflect), output cropped.
        h, w = x.shape[2], x.shape[3]
        ph, pw = -h % 16, -w % 16
        if ph or pw:
            mode = "reflect" if ph < h and pw < w else "constant"
            return self._forward(F.pad(x, (0, pw, 0, ph), mode=mode))[:, :, :h, :w]
        return self._forward(x)

    def _forward(self, x):
        skips = []
        for level, block in enumerate(self.down):
            x = block(x)
            if level < 4:
                skips.append(x)
                x = F.max_pool2d(x, 2, 2)
        for up, merge in zip(self.up, self.merge):
            x = merge(torch.cat([up(x), skips.pop()], 1))
        return self.head(x)


# --------------------------------------------------------------------------
# SR3 velocity field
# --------------------------------------------------------------------------
def conv3(cin, cout, stride=1):
    return nn.Conv2d(cin, cout, 3, stride=stride, padding=1)


class SelfAttention(nn.Module):
    def __init__(self, c, groups):
        super().__init__()
        self.norm = nn.GroupNorm(groups, c, eps=1e-5)
        self.qkv = nn.Conv2d(c, 3 * c, 1)
        self.out = nn.Conv2d(c, c, 1)

    def forward(self, x):
        n, c, h, w = x.shape
        qkv = self.qkv(self.norm(x)).reshape(n, 3 * c, h * w)
        q, k, v = qkv[:, :c], qkv[:, c:2 * c], qkv[:, 2 * c:]
        # weights[n, i, j] = softmax_j(q_i . k_j / sqrt(c)); out_i = sum_j w v_j.
        scores = q.transpose(1, 2).matmul(k) / math.sqrt(c)
        weights = torch.softmax(scores, 2)
        out = v.matmul(weights.transpose(1, 2)).reshape(n, c, h, w)
        return x + self.out(out)


class ResBlock(nn.Module):
    def __init__(self, cin, cout, emb, groups, dropout, attn):
        super().__init__()
        self.norm1 = nn.GroupNorm(groups, cin, eps=1e-5)
        self.conv1 = conv3(cin, cout)
        self.emb = nn.Linear(emb, cout)
        self.norm2 = nn.GroupNorm(groups, cout, eps=1e-5)
        self.dropout = nn.Dropout(dropout)
        self.conv2 = conv3(cout, cout)
        self.skip = nn.Conv2d(cin, cout, 1) if cin != cout else None
        self.attn = SelfAttention(cout, groups) if attn else None

    def forward(self, x, emb):
        n = x.shape[0]
        h = self.conv1(F.silu(self.norm1(x)))
        h = h + self.emb(emb).reshape(n, -1, 1, 1)
        h = self.conv2(self.dropout(F.silu(self.norm2(h))))
        res = self.skip(x) if self.skip is not None else x
        out = h + res
        return self.attn(out) if self.attn is not None else out


def time_embedding(t, dim):
    half = dim // 2
    k = torch.arange(half, dtype=torch.float32, device=t.device)
    freqs = torch.exp(-math.log(10000.0) * k / half).reshape(1, half)
    arg = t.reshape(-1, 1).matmul(freqs)
    return torch.cat([arg.sin(), arg.cos()], 1)


class Sr3Unet(nn.Module):
    def __init__(self, in_channels=8, out_channels=4, inner=64,
                 mults=(1, 2, 4, 8, 8), res_blocks=2, attn_levels=(3,),
                 groups=32, dropout=0.0):
        super().__init__()
        self.inner, self.levels, self.res_blocks = inner, len(mults), res_blocks

        def block(cin, cout, attn):
            return ResBlock(cin, cout, inner, groups, dropout, attn)

        feats = [inner]
        pre = inner
        self.downs = nn.ModuleList()
        self.downsamples = nn.ModuleList()
        for level, mult in enumerate(mults):
            ch = inner * mult
            attn = level in attn_levels
            for _ in range(res_blocks):
                self.downs.append(block(pre, ch, attn))
                feats.append(ch)
                pre = ch
            if level + 1 < len(mults):
                self.downsamples.append(conv3(pre, pre, 2))
                feats.append(pre)
        self.mid = nn.ModuleList([block(pre, pre, True), block(pre, pre, False)])
        self.ups = nn.ModuleList()
        self.upsamples = nn.ModuleList()
        for level in reversed(range(len(mults))):
            ch = inner * mults[level]
            attn = level in attn_levels
            for _ in range(res_blocks + 1):
                skip = feats.pop()
                self.ups.append(block(pre + skip, ch, attn))
                pre = ch
            if level > 0:
                self.upsamples.append(conv3(pre, pre, 1))
        self.first = conv3(in_channels, inner)
        self.t_in = nn.Linear(inner, 4 * inner)
        self.t_out = nn.Linear(4 * inner, inner)
        self.final_norm = nn.GroupNorm(groups, pre, eps=1e-5)
        self.final_conv = conv3(pre, out_channels)

    def forward(self, xt, cond, t):
        m = 1 << (self.levels - 1)
        assert xt.shape[2] % m == 0 and xt.shape[3] % m == 0
        x = torch.cat([cond, xt], 1)
        emb = self.t_out(F.silu(self.t_in(time_embedding(t, self.inner))))
        x = self.first(x)
        feats = [x]
        res = iter(self.downs)
        for level in range(self.levels):
            for _ in range(self.res_blocks):
                x = next(res)(x, emb)
                feats.append(x)
            if level + 1 < self.levels:
                x = self.downsamples[level](x)
                feats.append(x)
        for b in self.mid:
            x = b(x, emb)
        ups, upsamples = iter(self.ups), iter(self.upsamples)
        for level in reversed(range(self.levels)):
            for _ in range(self.res_blocks + 1):
                x = next(ups)(torch.cat([x, feats.pop()], 1), emb)
            if level > 0:
                x = F.interpolate(x, scale_factor=2, mode="nearest")
                x = next(upsamples)(x)
        return self.final_conv(F.silu(self.final_norm(x)))


# --------------------------------------------------------------------------
# Timing
# --------------------------------------------------------------------------
def sync(device):
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def timed(fn, warmup, iters, device):
    for _ in range(warmup):
        fn()
    sync(device)
    ts = []
    for _ in range(iters):
        t0 = time.perf_counter()
        fn()
        sync(device)
        ts.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(ts), min(ts)


def bench(name, args, gen):
    n, s = args.batch, args.size
    dev = torch.device(args.device)
    if dev.type == "cuda":
        torch.cuda.reset_peak_memory_stats(dev)
    if name == "unet":
        net = SidUnet(args.width).to(dev)
        noisy = torch.rand(n, 4, s, s, generator=gen).to(dev)
        clean = torch.rand(n, 4, s, s, generator=gen).to(dev)

        def fwd():
            with torch.no_grad():
                return net(noisy)

        def loss_fn():
            return (net(noisy) - clean).abs().mean()
    else:
        net = Sr3Unet().to(dev)
        cond = torch.rand(n, 4, s, s, generator=gen).to(dev)
        x1 = torch.rand(n, 4, s, s, generator=gen).to(dev)
        x0 = torch.randn(n, 4, s, s, generator=gen).to(dev)
        t = torch.rand(n, generator=gen).to(dev)
        t4 = t.reshape(n, 1, 1, 1)
        xt_fixed = x1 * t4 + x0 * (1 - t4)

        def fwd():
            with torch.no_grad():
                return net(xt_fixed, cond, t)

        def loss_fn():
            xt = x1 * t4 + x0 * (1 - t4)
            return ((x1 - x0) - net(xt, cond, t)).abs().mean()

    params = sum(p.numel() for p in net.parameters())
    opt = torch.optim.Adam(net.parameters(), lr=1e-4, eps=1e-5)
    net.train()

    def step():
        opt.zero_grad(set_to_none=True)
        loss = loss_fn()
        loss.backward()
        opt.step()
        return loss.item()

    fwd_ms, fwd_min = timed(fwd, args.warmup, args.iters, dev)
    step_ms, step_min = timed(step, args.warmup, args.iters, dev)
    if args.profile:
        profile(name, fwd, step)
    peak = torch.cuda.max_memory_allocated(dev) / 2**20 if dev.type == "cuda" else None
    return {
        "peak_gpu_mib": peak,
        "params": params,
        "rust_params": RUST_PARAMS[name] if args.width == 32 or name == "sr3" else None,
        "forward_ms": fwd_ms,
        "forward_ms_min": fwd_min,
        "train_step_ms": step_ms,
        "train_step_ms_min": step_min,
    }


def profile(name, fwd, step):
    from torch.profiler import ProfilerActivity, profile as prof

    for label, fn in (("forward", fwd), ("train step", step)):
        with prof(activities=[ProfilerActivity.CPU]) as p:
            for _ in range(3):
                fn()
        print(f"== torch profile: {name} {label} (3 runs) ==", file=sys.stderr)
        print(p.key_averages().table(sort_by="self_cpu_time_total", row_limit=18),
              file=sys.stderr)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--net", choices=["unet", "sr3", "both"], default="both")
    ap.add_argument("--batch", type=int, default=2)
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--width", type=int, default=32)
    ap.add_argument("--iters", type=int, default=10)
    ap.add_argument("--warmup", type=int, default=2)
    ap.add_argument("--threads", type=int, default=None,
                    help="torch.set_num_threads (default: torch's own choice)")
    ap.add_argument("--expect-params", type=str, default=None,
                    help='JSON {"unet": N, "sr3": N} from pgrf-bench train; checked')
    ap.add_argument("--device", default="cpu",
                    help="cpu or cuda (the GPU's default stream, synchronised around each timed call)")
    ap.add_argument("--no-tf32", action="store_true",
                    help="on CUDA, convolutions in strict f32 (cuDNN's TF32 off; PyTorch allows it by default)")
    ap.add_argument("--profile", action="store_true",
                    help="also print torch.profiler tables to stderr")
    args = ap.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
        torch.set_num_interop_threads(1)
    if args.expect_params:
        for k, v in json.loads(args.expect_params).items():
            RUST_PARAMS[k] = v
    if args.no_tf32:
        torch.backends.cudnn.allow_tf32 = False
        torch.backends.cuda.matmul.allow_tf32 = False
    torch.manual_seed(0)
    gen = torch.Generator().manual_seed(0)
    nets = ["unet", "sr3"] if args.net == "both" else [args.net]
    out = {
        "torch": torch.__version__,
        "threads": torch.get_num_threads(),
        "mkldnn": torch.backends.mkldnn.is_available(),
        "device": torch.cuda.get_device_name() if args.device.startswith("cuda") else "cpu",
        "cudnn_tf32": torch.backends.cudnn.allow_tf32 if args.device.startswith("cuda") else None,
        "batch": args.batch,
        "size": args.size,
        "width": args.width,
        "iters": args.iters,
        "warmup": args.warmup,
    }
    ok = True
    for name in nets:
        r = bench(name, args, gen)
        if r["rust_params"] is not None and r["params"] != r["rust_params"]:
            print(f"{name}: PyTorch has {r['params']} parameters, pgrf {r['rust_params']}",
                  file=sys.stderr)
            ok = False
        out[name] = r
    print(json.dumps(out))
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
