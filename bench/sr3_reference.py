#!/usr/bin/env python3
"""PyTorch reference for pgrf's PGRF velocity field (`Sr3Unet`,
crates/nn/src/sr3.rs): loads `pgrf export-weights` output (pgrf's own tensor
names) with load_state_dict(strict=True) and computes what pgrf's
`Sr3Unet::forward(xt, cond, t)` computes. Its fixtures are the ones
crates/nn/tests/sr3_torch.rs checks pgrf against (crates/nn/tests/data/sr3/).

    cargo build -p pgrf-cli
    target/debug/pgrf export-weights models/pgrf.safetensors -o /tmp/pgrf.pth
    /tmp/tv/bin/python bench/sr3_reference.py fixtures /tmp/pgrf.pth --config models/pgrf.safetensors

`fixtures` (re)computes every case's torch output from the exported weights
(the inputs in crates/nn/tests/data/sr3/ are kept; `--inputs` redraws them)
and records the SHA-256 of the --config weight file in io.json. These three
commands are what to run after models/pgrf.safetensors is retrained. One
case by hand (the main one, t = 0.3):

    /tmp/tv/bin/python bench/sr3_reference.py check /tmp/pgrf.pth \\
        crates/nn/tests/data/sr3/xt.f32 crates/nn/tests/data/sr3/cond.f32 \\
        crates/nn/tests/data/sr3/torch_output.f32 --t 0.3 --shape 1,4,32,32 \\
        --config models/pgrf.safetensors [--save OUT.f32] [--float64] [--tol T]

`check` loads a .pth (torch.load(weights_only=True)) or .safetensors (pgrf's
own weight file or its export), runs it on raw little-endian f32 Xt and T
(N,4,H,W) at t (one value, or one per batch item, comma-separated), prints
the max abs difference from EXPECTED (raw f32), optionally saves the output.

The architecture, read from sr3.rs line by line:

- Input: x = cat([T, Xt], 1) (8 planes, the condition first). Sides that are
  not multiples of m = 2^(levels - 1) are padded at the bottom and right to
  the next multiple, by reflection (edge excluded, torch's 'reflect') when
  both pads are smaller than their side, else by zeros; the output is
  cropped back to H x W before the residual step.
- Time: t in [0, 1] is embedded as is (no x1000): with half = inner/2,
  f_k = exp(-ln(10000) k / half), k = 0 .. half-1, e = [sin(t f), cos(t f)]
  (all sines first). emb = t_out(SiLU(t_in(e))): inner -> 4 inner -> inner.
- Linear layers are burn's: weight stored (in, out), y = x W + b (the
  transpose of torch.nn.Linear's layout), hence `BurnLinear` here.
- GroupNorm is burn's: parameters `gamma`/`beta` (torch: weight/bias), eps
  1e-5 (burn's default; NOT in the weight file), biased variance, groups =
  the config's norm_groups (NOT in the tensors: the export's .pth has no
  config, so it comes from the pgrf record or --norm-groups).
- Every 3x3 convolution has zero padding 1; downsampling is a 3x3 stride-2
  convolution (padding 1); upsampling is nearest x2 then a 3x3 convolution.
- ResBlock(cin, cout): h = conv1(SiLU(norm1(x))); h += emb_linear(emb)
  broadcast over pixels (the per-block linear takes the MLP's output
  directly: no SiLU between t_out and it); h = conv2(dropout(SiLU(norm2(h))));
  out = h + (skip 1x1 conv(x) if cin != cout else x); then, in blocks with
  attention, out = SelfAttention(out).
- SelfAttention(c): single head. qkv = 1x1 conv(GroupNorm(x)) to 3c planes
  (q, k, v in that order along the channels), scores q_i . k_j / sqrt(c),
  softmax over j, out = x + 1x1 conv(attended v). Part of the ResBlock
  module (`downs.N.attn.*`), applied after the block's residual sum.
- U-Net: first 3x3 conv (8 -> inner); feats = [x]. Per level l (channels
  inner * channel_mults[l]): res_blocks ResBlocks (attention where l is in
  attn_levels), each output pushed on feats; then, except at the last
  level, the stride-2 conv, its output pushed too. Middle: ResBlock with
  attention (always, whatever attn_levels says), ResBlock without. Up,
  levels from the deepest: res_blocks + 1 ResBlocks, each on
  cat([x, feats.pop()], 1) (the path first, the skip second); then, except
  at level 0, nearest x2 + 3x3 conv. Head: final_conv(SiLU(final_norm(x))).
- residual = true (the shipped model): out = (T + head - Xt) /
  max(1 - t, 0.1) per batch item (0.1 is a constant of sr3.rs, not in the
  weight file); residual = false: out = head.

No Python runs in the Rust test; this script only makes its fixtures.
"""
import argparse
import hashlib
import json
import math
import os
import struct

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

# Constants of pgrf's forward that no weight file holds.
GROUP_NORM_EPS = 1e-5  # burn::nn::GroupNormConfig's default epsilon
RESIDUAL_FLOOR = 0.1  # sr3.rs RESIDUAL_FLOOR
TIME_BASE = 10000.0  # sr3.rs time_embedding

DEFAULT_CONFIG = dict(  # Sr3Config::new()
    in_channels=8,
    out_channels=4,
    inner_channels=64,
    channel_mults=[1, 2, 4, 8, 8],
    res_blocks=2,
    attn_levels=[3],
    norm_groups=32,
    dropout=0.0,
    residual=False,
)

DATA_DIR = os.path.join("crates", "nn", "tests", "data", "sr3")
# The fixture cases: name, file prefix, shape, t per batch item, input seed.
# main: the brief's case (no padding: 32 is a multiple of 8 for 4 levels).
# reflect: batch of 2 with two t (one at the 0.1 floor: 1 - 0.95 < 0.1),
#   sides 12 x 20 padded to 16 x 24 by reflection.
# zeros: 4 x 6 padded to 8 x 8 by zeros (the pad of 4 rows is not < 4).
CASES = [
    dict(name="main", prefix="", shape=[1, 4, 32, 32], t=[0.3], seed=1),
    dict(name="reflect", prefix="reflect_", shape=[2, 4, 12, 20], t=[0.0, 0.95], seed=2),
    dict(name="zeros", prefix="zeros_", shape=[1, 4, 4, 6], t=[0.6], seed=3),
]

REGENERATE = (
    "cargo build -p pgrf-cli && "
    "target/debug/pgrf export-weights models/pgrf.safetensors -o /tmp/pgrf.pth && "
    "/tmp/tv/bin/python bench/sr3_reference.py fixtures /tmp/pgrf.pth --config models/pgrf.safetensors"
)


class BurnLinear(nn.Module):
    """burn's Linear: weight (in, out), y = x W + b."""

    def __init__(self, cin, cout):
        super().__init__()
        self.weight = nn.Parameter(torch.empty(cin, cout))
        self.bias = nn.Parameter(torch.zeros(cout))
        nn.init.normal_(self.weight, std=cin**-0.5)

    def forward(self, x):
        return x @ self.weight + self.bias


class BurnGroupNorm(nn.Module):
    """burn's GroupNorm: affine parameters named gamma and beta."""

    def __init__(self, groups, channels, eps=GROUP_NORM_EPS):
        super().__init__()
        if channels % groups:
            raise ValueError("norm_groups %d does not divide %d channels" % (groups, channels))
        self.groups = groups
        self.eps = eps
        self.gamma = nn.Parameter(torch.ones(channels))
        self.beta = nn.Parameter(torch.zeros(channels))

    def forward(self, x):
        return F.group_norm(x, self.groups, self.gamma, self.beta, self.eps)


def conv3(cin, cout, stride=1):
    return nn.Conv2d(cin, cout, 3, stride=stride, padding=1)


class SelfAttention(nn.Module):
    def __init__(self, c, groups):
        super().__init__()
        self.norm = BurnGroupNorm(groups, c)
        self.qkv = nn.Conv2d(c, 3 * c, 1)
        self.out = nn.Conv2d(c, c, 1)

    def forward(self, x):
        n, c, h, w = x.shape
        qkv = self.qkv(self.norm(x)).reshape(n, 3 * c, h * w)
        q, k, v = qkv[:, :c], qkv[:, c : 2 * c], qkv[:, 2 * c :]
        scores = q.transpose(1, 2) @ k / math.sqrt(c)  # (n, i, j)
        weights = torch.softmax(scores, dim=2)
        out = (v @ weights.transpose(1, 2)).reshape(n, c, h, w)
        return x + self.out(out)


class ResBlock(nn.Module):
    def __init__(self, cin, cout, emb, groups, dropout, attn):
        super().__init__()
        self.norm1 = BurnGroupNorm(groups, cin)
        self.conv1 = conv3(cin, cout)
        self.emb = BurnLinear(emb, cout)
        self.norm2 = BurnGroupNorm(groups, cout)
        self.dropout = nn.Dropout(dropout)
        self.conv2 = conv3(cout, cout)
        self.skip = nn.Conv2d(cin, cout, 1) if cin != cout else None
        self.attn = SelfAttention(cout, groups) if attn else None

    def forward(self, x, emb):
        h = self.conv1(F.silu(self.norm1(x)))
        h = h + self.emb(emb)[:, :, None, None]
        h = self.conv2(self.dropout(F.silu(self.norm2(h))))
        out = h + (self.skip(x) if self.skip is not None else x)
        return self.attn(out) if self.attn is not None else out


def time_embedding(t, dim):
    """[sin(t f_k), cos(t f_k)], f_k = 10000^(-k / half), computed in t's
    dtype the way sr3.rs does in f32: exp((-ln 10000 * k) / half)."""
    half = dim // 2
    k = torch.arange(half, dtype=t.dtype)
    freqs = torch.exp(torch.tensor(-math.log(TIME_BASE), dtype=t.dtype) * k / half)
    arg = t[:, None] * freqs[None, :]
    return torch.cat([torch.sin(arg), torch.cos(arg)], 1)


class Sr3Unet(nn.Module):
    """pgrf's Sr3Unet; keyword arguments are Sr3Config's fields."""

    def __init__(self, **config):
        super().__init__()
        unknown = set(config) - set(DEFAULT_CONFIG)
        if unknown:
            raise ValueError("unknown Sr3Config fields %s" % sorted(unknown))
        cfg = dict(DEFAULT_CONFIG, **config)
        self.config = cfg
        inner, mults = cfg["inner_channels"], list(cfg["channel_mults"])
        groups, attn_levels = cfg["norm_groups"], set(cfg["attn_levels"])
        self.inner, self.levels, self.res_blocks = inner, len(mults), cfg["res_blocks"]
        self.residual = bool(cfg["residual"])

        def block(cin, cout, attn):
            return ResBlock(cin, cout, inner, groups, cfg["dropout"], attn)

        feats, pre = [inner], inner
        downs, downsamples = [], []
        for level, mult in enumerate(mults):
            ch = inner * mult
            for _ in range(self.res_blocks):
                downs.append(block(pre, ch, level in attn_levels))
                feats.append(ch)
                pre = ch
            if level + 1 < self.levels:
                downsamples.append(conv3(pre, pre, 2))
                feats.append(pre)
        mid = [block(pre, pre, True), block(pre, pre, False)]
        ups, upsamples = [], []
        for level in reversed(range(self.levels)):
            ch = inner * mults[level]
            for _ in range(self.res_blocks + 1):
                ups.append(block(pre + feats.pop(), ch, level in attn_levels))
                pre = ch
            if level > 0:
                upsamples.append(conv3(pre, pre, 1))
        self.first = conv3(cfg["in_channels"], inner)
        self.t_in = BurnLinear(inner, 4 * inner)
        self.t_out = BurnLinear(4 * inner, inner)
        self.downs = nn.ModuleList(downs)
        self.downsamples = nn.ModuleList(downsamples)
        self.mid = nn.ModuleList(mid)
        self.ups = nn.ModuleList(ups)
        self.upsamples = nn.ModuleList(upsamples)
        self.final_norm = BurnGroupNorm(groups, pre)
        self.final_conv = conv3(pre, cfg["out_channels"])

    def forward(self, xt, cond, t):
        """v(Xt, T, t): xt and cond (N, 4, H, W), t (N,)."""
        n, _, h, w = xt.shape
        m = 1 << (self.levels - 1)
        ph, pw = (m - h % m) % m, (m - w % m) % m
        x = torch.cat([cond, xt], 1)
        if ph + pw > 0:
            if ph < h and pw < w:
                x = F.pad(x, (0, pw, 0, ph), mode="reflect")
            else:
                x = F.pad(x, (0, pw, 0, ph), mode="constant", value=0.0)
        emb = self.t_out(F.silu(self.t_in(time_embedding(t, self.inner))))

        x = self.first(x)
        feats = [x]
        downs = iter(self.downs)
        for level in range(self.levels):
            for _ in range(self.res_blocks):
                x = next(downs)(x, emb)
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
        out = self.final_conv(F.silu(self.final_norm(x)))[:, :, :h, :w]
        if self.residual:
            scale = (1.0 - t).clamp_min(RESIDUAL_FLOOR).reshape(n, 1, 1, 1)
            return (out + (cond - xt)) / scale
        return out


# ---- files ------------------------------------------------------------------


def safetensors_metadata(path):
    """The __metadata__ of a safetensors file (no tensors read)."""
    with open(path, "rb") as f:
        (size,) = struct.unpack("<Q", f.read(8))
        header = json.loads(f.read(size))
    return header.get("__metadata__") or {}


def pgrf_config(path):
    """Sr3Config of a pgrf weight file (its 'pgrf' record)."""
    meta = safetensors_metadata(path)
    if "pgrf" not in meta:
        raise SystemExit("%s has no pgrf record (not a pgrf weight file?)" % path)
    rec = json.loads(meta["pgrf"])
    if rec.get("arch") != "sr3":
        raise SystemExit("%s holds a %s network, not sr3 (PGRF)" % (path, rec.get("arch")))
    return rec["config"]


def load_state_dict_file(path):
    if path.endswith(".safetensors"):
        from safetensors.torch import load_file

        sd = load_file(path)
    else:
        sd = torch.load(path, map_location="cpu", weights_only=True)
    bad = [k for k, v in sd.items() if not torch.is_tensor(v)]
    if bad:
        raise SystemExit("%s: %s is not a tensor" % (path, bad[0]))
    return sd


def resolve_config(weights, config_path, overrides):
    """The config: the pgrf record of --config, else of the weight file
    itself, else pgrf's defaults; then command-line overrides."""
    if config_path:
        cfg = pgrf_config(config_path)
    elif weights.endswith(".safetensors") and "pgrf" in safetensors_metadata(weights):
        cfg = pgrf_config(weights)
    else:
        raise SystemExit(
            "%s carries no architecture (an exported .pth has none): give --config "
            "models/pgrf.safetensors (the file it was exported from)" % weights
        )
    cfg = dict(cfg)
    cfg.update({k: v for k, v in overrides.items() if v is not None})
    return cfg


def build(weights, config_path=None, overrides=None, dtype=torch.float32):
    cfg = resolve_config(weights, config_path, overrides or {})
    net = Sr3Unet(**cfg)
    sd = load_state_dict_file(weights)
    net.load_state_dict({k: v.to(torch.float32) for k, v in sd.items()}, strict=True)
    return net.to(dtype).eval(), cfg


def read_f32(path, shape):
    a = np.fromfile(path, dtype="<f4")
    if a.size != int(np.prod(shape)):
        raise SystemExit("%s holds %d floats, shape %s needs %d" % (path, a.size, shape, int(np.prod(shape))))
    return torch.from_numpy(a.reshape(shape).astype(np.float32))


def write_f32(path, x):
    np.ascontiguousarray(x.detach().to(torch.float32).numpy()).astype("<f4").tofile(path)


def sha256(path):
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def parse_t(s, n):
    t = [float(v) for v in s.split(",")]
    if len(t) == 1:
        t = t * n
    if len(t) != n:
        raise SystemExit("--t gives %d values for a batch of %d" % (len(t), n))
    return torch.tensor(t, dtype=torch.float32)


def run(net, xt, cond, t, dtype):
    with torch.no_grad():
        return net(xt.to(dtype), cond.to(dtype), t.to(dtype))


# ---- commands -----------------------------------------------------------------


def overrides_of(args):
    return dict(
        norm_groups=args.norm_groups,
        residual=None if args.residual is None else args.residual == "true",
    )


def check(args):
    torch.set_num_threads(1)
    shape = [int(s) for s in args.shape.split(",")]
    dtype = torch.float64 if args.float64 else torch.float32
    net, cfg = build(args.weights, args.config, overrides_of(args), dtype)
    xt, cond = read_f32(args.xt, shape), read_f32(args.cond, shape)
    t = parse_t(args.t, shape[0])
    y = run(net, xt, cond, t, dtype)
    nparams = sum(p.numel() for p in net.parameters())
    print("config %s; %d parameters; output %s, max abs %.6g" % (json.dumps(cfg), nparams, list(y.shape), float(y.abs().max())))
    if args.save:
        write_f32(args.save, y)
        print("wrote %s" % args.save)
    if args.expected is None:
        return
    e = read_f32(args.expected, list(y.shape)).to(dtype)
    diff = float((y - e).abs().max())
    print("max abs difference from %s: %.6g" % (args.expected, diff))
    if args.tol is not None and not diff <= args.tol:
        raise SystemExit(1)


def draw_inputs(case):
    """X_t on the straight path between N(0, 1) and a clean image, and T the
    clean image plus Gaussian noise: numpy's PCG64 seeded per case."""
    rng = np.random.default_rng(case["seed"])
    shape = case["shape"]
    t = np.array(case["t"], dtype=np.float32).reshape(-1, 1, 1, 1)
    clean = rng.uniform(0.0, 1.0, shape).astype(np.float32)
    cond = (clean + rng.normal(0.0, 0.1, shape)).astype(np.float32)
    x0 = rng.normal(0.0, 1.0, shape).astype(np.float32)
    xt = (t * clean + (1.0 - t) * x0).astype(np.float32)
    return xt, cond


def fixtures(args):
    torch.set_num_threads(1)
    d = args.dir
    os.makedirs(d, exist_ok=True)
    net, cfg = build(args.weights, args.config, overrides_of(args))
    net64 = Sr3Unet(**cfg)
    net64.load_state_dict(net.state_dict(), strict=True)
    net64 = net64.double().eval()
    source = args.config or args.weights
    # The exported tensors must be the weight file's own (export changes no value).
    if args.config:
        from safetensors.torch import load_file

        own, exported = load_file(args.config), load_state_dict_file(args.weights)
        if sorted(own) != sorted(exported) or any(not torch.equal(own[k], exported[k]) for k in own):
            raise SystemExit("%s does not hold %s's tensors" % (args.weights, args.config))
    cases = []
    for case in CASES:
        p = lambda f: os.path.join(d, case["prefix"] + f)
        if args.inputs or not os.path.exists(p("xt.f32")):
            xt, cond = draw_inputs(case)
            xt.astype("<f4").tofile(p("xt.f32"))
            cond.astype("<f4").tofile(p("cond.f32"))
        xt, cond = read_f32(p("xt.f32"), case["shape"]), read_f32(p("cond.f32"), case["shape"])
        t = torch.tensor(case["t"], dtype=torch.float32)
        y = run(net, xt, cond, t, torch.float32)
        y64 = run(net64, xt, cond, t, torch.float64)
        write_f32(p("torch_output.f32"), y)
        d64 = float((y.double() - y64).abs().max())
        print(
            "%-8s %s t=%s: output max abs %.4g, |float32 - float64| max %.3g"
            % (case["name"], case["shape"], case["t"], float(y.abs().max()), d64)
        )
        cases.append(
            dict(
                case,
                xt=case["prefix"] + "xt.f32",
                cond=case["prefix"] + "cond.f32",
                output=case["prefix"] + "torch_output.f32",
                output_max_abs=float(y.abs().max()),
                float32_vs_float64=d64,
            )
        )
    io = dict(
        weights=os.path.basename(source),
        weights_sha256=sha256(source),
        config=cfg,
        torch=torch.__version__,
        made_by="bench/sr3_reference.py fixtures",
        regenerate=REGENERATE,
        cases=cases,
    )
    with open(os.path.join(d, "io.json"), "w") as f:
        json.dump(io, f, indent=1)
        f.write("\n")
    print("wrote %s (weights sha256 %s)" % (os.path.join(d, "io.json"), io["weights_sha256"]))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)

    def common(p):
        p.add_argument("weights", help=".pth (torch.load weights_only=True) or .safetensors in pgrf's names")
        p.add_argument("--config", help="pgrf weight file whose record gives the architecture (needed for a .pth)")
        p.add_argument("--norm-groups", type=int, help="override the record's norm_groups")
        p.add_argument("--residual", choices=["true", "false"], help="override the record's residual")

    c = sub.add_parser("check", help="run WEIGHTS on XT, COND at t; compare with EXPECTED")
    common(c)
    c.add_argument("xt")
    c.add_argument("cond")
    c.add_argument("expected", nargs="?", help="raw f32 output to compare with (optional with --save)")
    c.add_argument("--t", required=True, help="t, or one per batch item, comma-separated")
    c.add_argument("--shape", required=True, help="N,C,H,W of XT and COND")
    c.add_argument("--save", help="write the output as raw little-endian f32")
    c.add_argument("--tol", type=float, help="exit 1 when the max abs difference exceeds this")
    c.add_argument("--float64", action="store_true", help="run in float64 (the float32 rounding reference)")
    f = sub.add_parser("fixtures", help="write the test's torch outputs (and inputs if missing) and io.json")
    common(f)
    f.add_argument("--dir", default=DATA_DIR)
    f.add_argument("--inputs", action="store_true", help="redraw the inputs too")
    args = ap.parse_args()
    if args.cmd == "check":
        check(args)
    else:
        fixtures(args)


if __name__ == "__main__":
    main()
