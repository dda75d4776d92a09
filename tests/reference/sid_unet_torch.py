#!/usr/bin/env python3
"""PyTorch reference for the SID U-Net ("UNetSeeInDark") as the published
raw -> raw denoisers define it, and the fixtures pgrf's checkpoint
importer/exporter is tested against (crates/nn/tests/data/sid_unet/).

    /tmp/tv/bin/pip install torch numpy safetensors
    python tests/reference/sid_unet_torch.py write crates/nn/tests/data/sid_unet
    python tests/reference/sid_unet_torch.py check FILE INPUT EXPECTED [--shape N,C,H,W] [--tol T] [--pgrf-pad]

The module and parameter names follow ELD (Vandermode/ELD,
models/arch/Unet.py), PMN (megvii-research/PMN, archs/ELD_models.py),
PNNP (fenghansen/PNNP, archs/Unet.py) and LED (Srameo/LED,
led/archs/unet_arch.py, class UNetArch): conv1_1 .. conv5_2, pool1 ..
pool4, upv6 .. upv9 (ConvTranspose2d, kernel 2, stride 2), conv6_1 ..
conv9_2, conv10_1 (1x1). Every 3x3 convolution (zero padding 1) is followed
by LeakyReLU(0.2) (ELD and LED write it torch.max(0.2 * x, x), PMN/PNNP
nn.LeakyReLU(0.2): the same values); the transposed convolutions and the
1x1 head have no activation. Skips are concatenated as torch.cat([up, skip],
1): the first half of conv6_1 .. conv9_1's input channels sees the upsampled
path, the second half the encoder's skip. No padding inside forward(): the
sides must be multiples of 16 (LED's UNetArch pads by reflection itself;
ELD, PMN and PNNP do not).

`write DIR` makes the fixtures (see `write` below and DIR/io.json);
`check FILE INPUT EXPECTED` loads a .pth (torch.load(weights_only=True))
or .safetensors into this module with load_state_dict(strict=True) (width,
in and out channels read from conv1_1.weight and conv10_1.weight), runs it
on INPUT (raw little-endian f32) and prints the max abs difference from
EXPECTED (raw little-endian f32). Nested checkpoints ('state_dict',
'netG', 'model', 'params', 'params_deploy', 'params_ema') and 'module.'
prefixes are unwrapped first, so every good fixture checks.

Never torch.load() DIR/malicious.pth: it runs `echo pwned` when unpickled
without weights_only (check refuses to touch it at all).
"""
import argparse
import hashlib
import io
import json
import os
import pickle
import pickletools
import struct
import sys
import zipfile

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

FULL_WIDTH = 32
FULL_WIDTH_PARAMS = 7_760_484
FIXTURE_WIDTH = 2
INPUT_SHAPE = (1, 4, 32, 48)
SEED_WEIGHTS = 0
SEED_INPUT = 1
SEED_OTHER = 2
BIAS_STD = 0.1
SUGGESTED_TOL = 1e-4
NESTED_KEYS = ("state_dict", "netG", "model", "params_deploy", "params_ema", "params")


class UNetSeeInDark(nn.Module):
    """The SID U-Net, raw -> raw, under the published parameter names."""

    def __init__(self, in_channels=4, out_channels=4, width=32):
        super().__init__()
        w = width
        conv3 = lambda a, b: nn.Conv2d(a, b, kernel_size=3, stride=1, padding=1)
        self.conv1_1 = conv3(in_channels, w)
        self.conv1_2 = conv3(w, w)
        self.pool1 = nn.MaxPool2d(kernel_size=2)
        self.conv2_1 = conv3(w, 2 * w)
        self.conv2_2 = conv3(2 * w, 2 * w)
        self.pool2 = nn.MaxPool2d(kernel_size=2)
        self.conv3_1 = conv3(2 * w, 4 * w)
        self.conv3_2 = conv3(4 * w, 4 * w)
        self.pool3 = nn.MaxPool2d(kernel_size=2)
        self.conv4_1 = conv3(4 * w, 8 * w)
        self.conv4_2 = conv3(8 * w, 8 * w)
        self.pool4 = nn.MaxPool2d(kernel_size=2)
        self.conv5_1 = conv3(8 * w, 16 * w)
        self.conv5_2 = conv3(16 * w, 16 * w)
        self.upv6 = nn.ConvTranspose2d(16 * w, 8 * w, 2, stride=2)
        self.conv6_1 = conv3(16 * w, 8 * w)
        self.conv6_2 = conv3(8 * w, 8 * w)
        self.upv7 = nn.ConvTranspose2d(8 * w, 4 * w, 2, stride=2)
        self.conv7_1 = conv3(8 * w, 4 * w)
        self.conv7_2 = conv3(4 * w, 4 * w)
        self.upv8 = nn.ConvTranspose2d(4 * w, 2 * w, 2, stride=2)
        self.conv8_1 = conv3(4 * w, 2 * w)
        self.conv8_2 = conv3(2 * w, 2 * w)
        self.upv9 = nn.ConvTranspose2d(2 * w, w, 2, stride=2)
        self.conv9_1 = conv3(2 * w, w)
        self.conv9_2 = conv3(w, w)
        self.conv10_1 = nn.Conv2d(w, out_channels, kernel_size=1, stride=1)

    @staticmethod
    def lrelu(x):
        return F.leaky_relu(x, 0.2)

    def forward(self, x):
        r = self.lrelu
        conv1 = r(self.conv1_2(r(self.conv1_1(x))))
        conv2 = r(self.conv2_2(r(self.conv2_1(self.pool1(conv1)))))
        conv3 = r(self.conv3_2(r(self.conv3_1(self.pool2(conv2)))))
        conv4 = r(self.conv4_2(r(self.conv4_1(self.pool3(conv3)))))
        conv5 = r(self.conv5_2(r(self.conv5_1(self.pool4(conv4)))))
        up6 = torch.cat([self.upv6(conv5), conv4], 1)
        conv6 = r(self.conv6_2(r(self.conv6_1(up6))))
        up7 = torch.cat([self.upv7(conv6), conv3], 1)
        conv7 = r(self.conv7_2(r(self.conv7_1(up7))))
        up8 = torch.cat([self.upv8(conv7), conv2], 1)
        conv8 = r(self.conv8_2(r(self.conv8_1(up8))))
        up9 = torch.cat([self.upv9(conv8), conv1], 1)
        conv9 = r(self.conv9_2(r(self.conv9_1(up9))))
        return self.conv10_1(conv9)


def param_count(module):
    return sum(p.numel() for p in module.parameters())


def pgrf_padded_forward(net, x):
    """pgrf's SidUnet::forward framing (crates/nn/src/unet.rs): pad bottom and
    right up to a multiple of 16, by reflection (edge not repeated, as burn's
    PadMode::Reflect and torch's 'reflect') when both pads are smaller than
    the sides, with zeros otherwise; crop the output back."""
    n, c, h, w = x.shape
    ph, pw = (-h) % 16, (-w) % 16
    if ph + pw > 0:
        mode = "reflect" if (ph < h and pw < w) else "constant"
        x = F.pad(x, (0, pw, 0, ph), mode=mode)
    return net(x)[:, :, :h, :w]


# ---------------------------------------------------------------- write


# Scale of the head's weights and bias after the He draw (see seeded_model).
HEAD_SCALE = 0.05


def fan_in(module):
    """Inputs summed into one output value: in * kh * kw for a convolution;
    in_channels for the 2x2 stride-2 transposed convolutions (each output
    pixel takes one kernel tap per input channel)."""
    w = module.weight
    if isinstance(module, nn.ConvTranspose2d):
        return w.shape[0] * w.shape[2] * w.shape[3] // (module.stride[0] * module.stride[1])
    return w.shape[1] * w.shape[2] * w.shape[3]


def seeded_model(width):
    """Weights N(0, 2 / fan_in) (He), biases N(0, BIAS_STD), drawn from
    torch.manual_seed(SEED_WEIGHTS) in state_dict order.

    Not N(0, 0.1) for the weights: at width 2 that shrinks the signal at
    every layer, the output is nearly the biases' constant, and mistakes in
    the deep half hardly show (swapping conv6_1's two input halves changed
    the output by 7e-6, zeroing conv5_2's bias by 3e-6). With He weights
    each such mistake changes it by 0.8 .. 23 (output std 3.8).

    The head (conv10_1) is then scaled by HEAD_SCALE so the output has the
    range of an image (std about 0.2, as a trained denoiser's [0, 1]
    output): float32 rounding then stays near 1e-6, and pgrf's Rust test
    can hold the match to 1e-5 absolute, while each mistake above still
    moves the output by 0.04 .. 1."""
    torch.manual_seed(SEED_WEIGHTS)
    net = UNetSeeInDark(4, 4, width)
    with torch.no_grad():
        for name, p in net.named_parameters():
            module = getattr(net, name.split(".")[0])
            if name.endswith(".weight"):
                p.normal_(0.0, (2.0 / fan_in(module)) ** 0.5)
            else:
                p.normal_(0.0, BIAS_STD)
        net.conv10_1.weight.mul_(HEAD_SCALE)
        net.conv10_1.bias.mul_(HEAD_SCALE)
    return net.eval()


def contiguous_sd(net):
    return {k: v.detach().clone().contiguous() for k, v in net.state_dict().items()}


class _Evil:
    """Unpickling this runs os.system('echo pwned'). Only ever pickled here."""

    def __reduce__(self):
        return (os.system, ("echo pwned",))


class _EvilOsSpelling:
    """The same call, written as GLOBAL 'os system' (see _OsSpellingPickler)."""

    def __reduce__(self):
        return (os.system, ("echo pwned",))


class _OsSpellingPickler(pickle._Pickler):
    """Pure-Python pickler that spells os.system as 'os system' for
    _EvilOsSpelling (the standard pickler writes 'posix system' on Linux,
    'nt system' on Windows: os.system.__module__ is the platform module)."""

    def __init__(self, *a, **k):
        super().__init__(*a, **k)
        self._os_spelling = False

    def save_reduce(self, func, args, *rest, obj=None, **kw):
        if func is os.system and isinstance(obj, _EvilOsSpelling):
            # Not memoized: the platform spelling below must be written too.
            self.write(pickle.GLOBAL + b"os\nsystem\n")
            self.save(args)
            self.write(pickle.REDUCE)
            if obj is not None:
                self.memoize(obj)
            return
        return super().save_reduce(func, args, *rest, obj=obj, **kw)


class _OsSpellingModule:
    Pickler = _OsSpellingPickler
    Unpickler = pickle.Unpickler
    HIGHEST_PROTOCOL = pickle.HIGHEST_PROTOCOL

    @staticmethod
    def dump(*a, **k):
        return pickle.dump(*a, **k)


def pkl_of(path):
    """The data.pkl record of a torch zip checkpoint (read, never loaded)."""
    with zipfile.ZipFile(path) as z:
        name = next(n for n in z.namelist() if n.endswith("/data.pkl"))
        return z.read(name)


def globals_and_reduces(pkl):
    """(GLOBAL/STACK_GLOBAL names, REDUCE count), by parsing the opcodes only."""
    names, reduces, strings = [], 0, []
    for op, arg, _ in pickletools.genops(pkl):
        if op.name == "GLOBAL":
            names.append(arg.replace(" ", "."))
        elif op.name == "STACK_GLOBAL":
            names.append(".".join(strings[-2:]))
        elif op.name == "REDUCE":
            reduces += 1
        if op.name in ("SHORT_BINUNICODE", "BINUNICODE", "UNICODE", "BINUNICODE8"):
            strings.append(arg)
    return names, reduces


class OtherArch(nn.Module):
    """A small conv net with other parameter names (not a SID U-Net)."""

    def __init__(self):
        super().__init__()
        self.head = nn.Conv2d(4, 8, 3, padding=1)
        self.body = nn.Sequential(nn.Conv2d(8, 8, 3, padding=1), nn.ReLU(), nn.Conv2d(8, 8, 3, padding=1))
        self.tail = nn.Conv2d(8, 4, 3, padding=1)


def f32_list(a):
    return [float(v) for v in np.asarray(a, dtype=np.float32).ravel()]


def f32_bits(a):
    return ["0x%08x" % struct.unpack("<I", struct.pack("<f", v))[0] for v in f32_list(a)]


def write(out_dir):
    torch.set_num_threads(1)
    os.makedirs(out_dir, exist_ok=True)
    p = lambda name: os.path.join(out_dir, name)

    # The full-width architecture: parameter count and names/shapes.
    full = UNetSeeInDark(4, 4, FULL_WIDTH)
    assert param_count(full) == FULL_WIDTH_PARAMS, param_count(full)
    with open(p("full_width_shapes.json"), "w") as f:
        json.dump(
            {
                "arch": "UNetSeeInDark",
                "width": FULL_WIDTH,
                "in_channels": 4,
                "out_channels": 4,
                "total_params": param_count(full),
                "state_dict": [[k, list(v.shape)] for k, v in full.state_dict().items()],
            },
            f,
            indent=1,
        )
        f.write("\n")
    del full

    net = seeded_model(FIXTURE_WIDTH)
    sd = contiguous_sd(net)

    # Good files.
    torch.save(sd, p("plain.pth"))
    torch.save({"state_dict": sd, "epoch": 7}, p("nested_state_dict.pth"))
    torch.save({"netG": sd, "iteration": 100}, p("nested_netG.pth"))
    torch.save({"model": sd}, p("nested_model.pth"))
    torch.save({"module." + k: v for k, v in sd.items()}, p("module_prefix.pth"))
    # ELD's layout in torch's legacy (pre-1.6, non-zip) format, as ELD's
    # July 2020 files may be: the network under 'netG' next to an Adam
    # state (one seeded step taken so it holds exp_avg tensors, ints and
    # float tuples).
    eld = seeded_model(FIXTURE_WIDTH)
    eld.load_state_dict(sd)
    opt = torch.optim.Adam(eld.parameters(), lr=1e-4)
    g = torch.Generator().manual_seed(2)
    eld(torch.rand((1, 4, 16, 16), generator=g)).abs().mean().backward()
    opt.step()
    torch.save(
        {"netG": sd, "opt_g": opt.state_dict(), "epoch": 200, "iterations": 1000},
        p("eld_legacy.pth"),
        _use_new_zipfile_serialization=False,
    )
    # LED's layout: BasicSR's {'params': sd, 'params_ema': ...}.
    torch.save({"params": sd, "params_ema": {k: v.clone() for k, v in sd.items()}}, p("led_params.pth"))
    from safetensors.torch import save_file

    save_file(sd, p("plain.safetensors"))
    os.chmod(p("plain.safetensors"), 0o644)  # safetensors creates it 0600

    # Input and output.
    g = torch.Generator().manual_seed(SEED_INPUT)
    x = torch.rand(INPUT_SHAPE, generator=g, dtype=torch.float32)
    with torch.no_grad():
        y = net(x)
        y64 = net.double()(x.double())
        net.float()
    y_np = y.numpy().astype("<f4")
    x.numpy().astype("<f4").tofile(p("input.f32"))
    y_np.tofile(p("output.f32"))

    # Bad files.
    torch.manual_seed(SEED_OTHER)
    torch.save(contiguous_sd(OtherArch()), p("other_arch.pth"))
    with open(p("plain.pth"), "rb") as f:
        plain_bytes = f.read()
    with open(p("truncated.pth"), "wb") as f:
        f.write(plain_bytes[: len(plain_bytes) // 2])
    non_tensor = dict(sd)
    non_tensor["conv10_1.bias"] = sd["conv10_1.bias"].tolist()
    torch.save(non_tensor, p("non_tensor.pth"))
    missing = {k: v for k, v in sd.items() if k != "conv10_1.bias"}
    torch.save(missing, p("missing_key.pth"))
    mismatch = dict(sd)
    good_shape = list(sd["conv1_1.weight"].shape)
    bad_shape = good_shape[:3] + [4]  # 3x3 kernel -> 3x4: no width/in-channel inference absorbs it
    mismatch["conv1_1.weight"] = torch.randn(bad_shape, generator=torch.Generator().manual_seed(SEED_OTHER))
    torch.save(mismatch, p("shape_mismatch.pth"))
    evil = {
        "conv10_1.bias": sd["conv10_1.bias"],
        "payload": _EvilOsSpelling(),
        "payload_platform": _Evil(),
    }
    torch.save(evil, p("malicious.pth"), pickle_module=_OsSpellingModule)
    names, reduces = globals_and_reduces(pkl_of(p("malicious.pth")))
    assert "os.system" in names and reduces >= 2, (names, reduces)
    platform_name = os.system.__module__ + ".system"
    assert platform_name in names, (names, platform_name)

    files = sorted(n for n in os.listdir(out_dir) if n != "io.json")
    io_doc = {
        "generator": "tests/reference/sid_unet_torch.py write",
        "torch": torch.__version__,
        "arch": "UNetSeeInDark",
        "width": FIXTURE_WIDTH,
        "in_channels": 4,
        "out_channels": 4,
        "params": param_count(net),
        "init": "torch.manual_seed(%d); in state_dict order, weights .normal_(0, sqrt(2 / fan_in)) "
        "(fan_in = in*kh*kw for Conv2d, in_channels for the 2x2 stride-2 ConvTranspose2d), biases .normal_(0, %g); "
        "then conv10_1's weight and bias times HEAD_SCALE = 0.05"
        % (SEED_WEIGHTS, BIAS_STD),
        "input": {
            "file": "input.f32",
            "shape": list(INPUT_SHAPE),
            "dtype": "float32 little-endian, C order, no header",
            "values": "torch.rand(shape, generator=torch.Generator().manual_seed(%d))" % SEED_INPUT,
            "first8": f32_list(x.numpy().ravel()[:8]),
        },
        "output": {
            "file": "output.f32",
            "shape": list(y.shape),
            "dtype": "float32 little-endian, C order, no header",
            "max_abs": float(np.abs(y_np).max()),
            "mean": float(y_np.astype(np.float64).mean()),
            "first8": f32_list(y_np.ravel()[:8]),
            "first8_bits": f32_bits(y_np.ravel()[:8]),
            "max_abs_diff_float32_vs_float64_forward": float(np.abs(y_np.astype(np.float64) - y64.numpy()).max()),
            "suggested_abs_tol": SUGGESTED_TOL,
        },
        "files": {
            "plain.pth": "torch.save(state_dict) (zip format)",
            "nested_state_dict.pth": "{'state_dict': sd, 'epoch': 7}",
            "nested_netG.pth": "{'netG': sd, 'iteration': 100}",
            "nested_model.pth": "{'model': sd}",
            "module_prefix.pth": "every key prefixed 'module.' (DataParallel)",
            "eld_legacy.pth": "{'netG': sd, 'opt_g': Adam state after one step, 'epoch': 200, 'iterations': 1000}, legacy non-zip format",
            "led_params.pth": "{'params': sd, 'params_ema': sd} (BasicSR, LED)",
            "plain.safetensors": "safetensors.torch.save_file(sd)",
            "other_arch.pth": "state dict of another conv net: head.*, body.0.*, body.2.*, tail.*",
            "truncated.pth": "first %d of plain.pth's %d bytes" % (len(plain_bytes) // 2, len(plain_bytes)),
            "non_tensor.pth": "plain with 'conv10_1.bias' a Python list of floats",
            "missing_key.pth": "plain minus 'conv10_1.bias'",
            "shape_mismatch.pth": "plain with 'conv1_1.weight' of shape %s instead of %s" % (bad_shape, good_shape),
            "malicious.pth": "NEVER torch.load without weights_only: {'conv10_1.bias': tensor, 'payload': "
            "REDUCE(GLOBAL 'os system', ('echo pwned',)), 'payload_platform': REDUCE(GLOBAL '%s system', ...)}"
            % os.system.__module__,
            "malicious_globals": names,
        },
        "sha256": {},
        "sizes": {},
    }
    for n in files:
        with open(p(n), "rb") as f:
            b = f.read()
        io_doc["sha256"][n] = hashlib.sha256(b).hexdigest()
        io_doc["sizes"][n] = len(b)
    with open(p("io.json"), "w") as f:
        json.dump(io_doc, f, indent=1)
        f.write("\n")
    total = sum(os.path.getsize(p(n)) for n in os.listdir(out_dir))
    print("wrote %d files, %d bytes, width %d (%d params)" % (len(files) + 1, total, FIXTURE_WIDTH, param_count(net)))


# ---------------------------------------------------------------- check


def unwrap(obj):
    """A flat {name: tensor} from a checkpoint object; 'module.' removed."""
    while isinstance(obj, dict) and not any(torch.is_tensor(v) for v in obj.values()):
        key = next((k for k in NESTED_KEYS if k in obj and isinstance(obj[k], dict)), None)
        if key is None:
            raise SystemExit("no state dict found under %s (keys: %s)" % (NESTED_KEYS, sorted(obj)[:10]))
        obj = obj[key]
    if not isinstance(obj, dict):
        raise SystemExit("checkpoint holds %s, not a state dict" % type(obj).__name__)
    return {(k[7:] if k.startswith("module.") else k): v for k, v in obj.items()}


def load_state_dict_file(path):
    if path.endswith(".safetensors"):
        from safetensors.torch import load_file

        return load_file(path)
    if os.path.basename(path) == "malicious.pth":
        raise SystemExit("refusing to open malicious.pth")
    try:
        obj = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # truncated zip, forbidden global, ...
        raise SystemExit("torch.load(weights_only=True) refused %s: %s: %s" % (path, type(e).__name__, str(e).splitlines()[0]))
    return unwrap(obj)


def read_f32(path, shape):
    a = np.fromfile(path, dtype="<f4")
    if a.size != int(np.prod(shape)):
        raise SystemExit("%s holds %d floats, shape %s needs %d" % (path, a.size, shape, int(np.prod(shape))))
    return torch.from_numpy(a.reshape(shape).astype(np.float32))


def check(args):
    torch.set_num_threads(1)
    sd = load_state_dict_file(args.file)
    for k, v in sd.items():
        if not torch.is_tensor(v):
            raise SystemExit("%s is a %s, not a tensor" % (k, type(v).__name__))
    for k in ("conv1_1.weight", "conv10_1.weight"):
        if k not in sd:
            raise SystemExit("no %s: not a UNetSeeInDark state dict" % k)
    width, cin = sd["conv1_1.weight"].shape[:2]
    cout = sd["conv10_1.weight"].shape[0]
    net = UNetSeeInDark(cin, cout, width)
    net.load_state_dict({k: v.float() for k, v in sd.items()}, strict=True)
    net.eval()
    if args.shape:
        shape = [int(s) for s in args.shape.split(",")]
    else:
        io_path = os.path.join(os.path.dirname(os.path.abspath(args.input)), "io.json")
        with open(io_path) as f:
            shape = json.load(f)["input"]["shape"]
    x = read_f32(args.input, shape)
    with torch.no_grad():
        if args.pgrf_pad:
            y = pgrf_padded_forward(net, x)
        else:
            if shape[2] % 16 or shape[3] % 16:
                raise SystemExit("sides %s are not multiples of 16 (the published nets need that; --pgrf-pad pads as pgrf does)" % shape[2:])
            y = net(x)
        if args.residual:
            y = y + x
    if args.save:
        y.numpy().astype("<f4").tofile(args.save)
        print("wrote %s: output %s, max abs %.6g" % (args.save, list(y.shape), float(y.abs().max())))
    if args.expected is None:
        return
    e = read_f32(args.expected, list(y.shape))
    diff = float((y - e).abs().max())
    print(
        "width %d, %d -> %d channels, %d params; output %s; max abs %.6g; max abs difference %.6g"
        % (width, cin, cout, param_count(net), list(y.shape), float(y.abs().max()), diff)
    )
    if args.tol is not None and not diff <= args.tol:
        raise SystemExit(1)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    w = sub.add_parser("write", help="write the fixtures into DIR")
    w.add_argument("dir")
    c = sub.add_parser("check", help="run FILE's weights on INPUT, compare with EXPECTED")
    c.add_argument("file")
    c.add_argument("input")
    c.add_argument("expected", nargs="?", help="raw f32 output to compare with (optional with --save)")
    c.add_argument("--residual", action="store_true", help="add the input to the output (pgrf's residual networks)")
    c.add_argument("--save", help="write the output as raw little-endian f32 to this file")
    c.add_argument("--shape", help="N,C,H,W of INPUT (default: io.json next to INPUT)")
    c.add_argument("--tol", type=float, help="exit 1 when the max abs difference exceeds this")
    c.add_argument("--pgrf-pad", action="store_true", help="pad/crop to multiples of 16 as pgrf's SidUnet does")
    args = ap.parse_args()
    if args.cmd == "write":
        write(args.dir)
    else:
        check(args)


if __name__ == "__main__":
    main()
