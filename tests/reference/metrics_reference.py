#!/usr/bin/env python3
"""Reference PSNR / SSIM / illuminance-gain values for pgrf-eval's tests.

Builds a few fixed, deterministic packed pairs (C, H, W) of float32 in the
way crates/eval/tests/reference.rs rebuilds them bit for bit, runs them
through the ELD evaluation protocol with numpy + scikit-image, and prints
one JSON line per case. The numbers are committed into
crates/eval/tests/reference.rs, so the Rust test suite never needs Python.

    python3 -m venv /tmp/skvenv && /tmp/skvenv/bin/pip install scikit-image numpy
    /tmp/skvenv/bin/python tests/reference/metrics_reference.py

Input generator (integer arithmetic and single IEEE float32 operations only,
so Rust and numpy produce identical bits; no sin/cos, whose last bits differ
between math libraries):

    reference[c, i, j] = f32(4 * tri + (7 i + 3 j) % 41) / f32(1100)
        tri = |(i + 2 j + 16 c) % 512 - 256|
    u = uniform draws from a 64-bit LCG (Knuth's MMIX constants),
        s <- s * 6364136223846793005 + 1442695040888963407  (mod 2^64),
        u = f32(s >> 40) / f32(2^24)                          (exact, in [0, 1))
        one draw per element in C order (c, i, j), the state seeded per case
        and advanced once before the first draw
    output = gain * reference + (u - 0.5) * amp     (each step one f32 op)

Protocol (ELD's models/ELD_model.py: IlluminanceCorrect, tensor2im,
util/index.py quality_assess), mirrored in pgrf_eval::evaluate:

    o = clip(output, 0, 1)                             float32
    if correct: g = dot(o[m], r[m]) / dot(o[m], o[m]), m = reference != 1
                (sums in float64; ELD sums in float32 torch.dot)
                o = float32(g) * o                     float32
    O = clip(o * 255, 0, 255), R = clip(reference * 255, 0, 255)   float32
    PSNR = peak_signal_noise_ratio(R, O, data_range=255)
    SSIM = structural_similarity(R, O, data_range=255, channel_axis=-1)
    on O, R converted to float64 (HWC layout, as ELD passes them).

Why float64: given float32 arrays (ELD's literal path) scikit-image runs
SSIM's filters in float32, where E[x^2] - E[x]^2 loses digits; the float64
numbers are the exact value of the same formula. The float32 numbers are
printed too ("*_f32") to document how far ELD's literal computation sits from
them; pgrf computes in f64 and matches the float64 numbers.
"""
import json
import sys

import numpy as np
import skimage
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

MASK64 = (1 << 64) - 1
LCG_A = 6364136223846793005
LCG_C = 1442695040888963407


def uniforms(seed, n):
    s = seed & MASK64
    out = np.empty(n, dtype=np.float32)
    for k in range(n):
        s = (s * LCG_A + LCG_C) & MASK64
        out[k] = np.float32(s >> 40) / np.float32(16777216.0)
    return out


def pattern(c, h, w):
    ref = np.empty((c, h, w), dtype=np.float32)
    for ch in range(c):
        for i in range(h):
            for j in range(w):
                tri = abs((i + 2 * j + 16 * ch) % 512 - 256)
                num = 4 * tri + (7 * i + 3 * j) % 41
                ref[ch, i, j] = np.float32(num) / np.float32(1100.0)
    return ref


def fnv1a(a):
    """FNV-1a 64 over the little-endian bytes of a float32 array (C order)."""
    h = 0xCBF29CE484222325
    for b in np.ascontiguousarray(a, dtype="<f4").tobytes():
        h = ((h ^ b) * 0x100000001B3) & MASK64
    return h


def make_case(name, shape, seed, amp, gain=1.0, saturate=None):
    c, h, w = shape
    ref = pattern(c, h, w)
    u = uniforms(seed, c * h * w).reshape(shape)
    out = np.float32(gain) * ref + (u - np.float32(0.5)) * np.float32(amp)
    if saturate is not None:
        (y0, y1), (x0, x1) = saturate
        # Saturated reference pixels, and deliberately wrong output values
        # there (0.25 .. 0.75 from the same draws): the gain must ignore them.
        ref[:, y0:y1, x0:x1] = np.float32(1.0)
        out[:, y0:y1, x0:x1] = np.float32(0.25) + u[:, y0:y1, x0:x1] * np.float32(0.5)
    assert out.dtype == np.float32 and ref.dtype == np.float32
    return dict(name=name, shape=shape, seed=seed, amp=amp, gain=gain, saturate=saturate, out=out, ref=ref)


CASES = [
    make_case("smooth_64x80", (4, 64, 80), 1, 0.1),
    make_case("odd_45x59", (4, 45, 59), 2, 0.3),
    make_case("small_9x11", (4, 9, 11), 3, 0.05),
    make_case("exact_7x7", (4, 7, 7), 4, 0.2),
    make_case("saturated_40x50", (4, 40, 50), 5, 0.05, saturate=((10, 25), (12, 30))),
    make_case("gain_48x52", (4, 48, 52), 6, 0.02, gain=0.8),
    make_case("one_channel_16x13", (1, 16, 13), 7, 0.1),
]


def eld_gain(out, ref):
    o = np.clip(out, np.float32(0), np.float32(1)).astype(np.float64)
    r = ref.astype(np.float64)
    m = ref != np.float32(1.0)
    num = float(np.dot(o[m], r[m]))
    den = float(np.dot(o[m], o[m]))
    return num / den


def x255(a, clamp):
    v = a * np.float32(255.0)
    if clamp:
        v = np.clip(v, np.float32(0), np.float32(255))
    assert v.dtype == np.float32
    return v


def protocol(out, ref, clamp, correct):
    g = None
    o = np.clip(out, np.float32(0), np.float32(1)) if (clamp or correct) else out
    if correct:
        g = eld_gain(out, ref)
        o = np.float32(g) * o
        assert o.dtype == np.float32
    return x255(o, clamp), x255(ref, clamp), g


def scores(O, R, dtype):
    # ELD passes HWC images; channel_axis=-1.
    Oh = np.transpose(O, (1, 2, 0)).astype(dtype)
    Rh = np.transpose(R, (1, 2, 0)).astype(dtype)
    p = peak_signal_noise_ratio(Rh, Oh, data_range=255)
    s = structural_similarity(Rh, Oh, data_range=255, channel_axis=-1)
    return float(p), float(s)


def main():
    print(f"# numpy {np.__version__}, scikit-image {skimage.__version__}", file=sys.stderr)
    for case in CASES:
        out, ref = case["out"], case["ref"]
        row = dict(name=case["name"], shape=list(case["shape"]), out_fnv=f"{fnv1a(out):#018x}", ref_fnv=f"{fnv1a(ref):#018x}")
        for label, clamp, correct in (("raw", False, False), ("eld", True, False), ("eld_corrected", True, True)):
            O, R, g = protocol(out, ref, clamp, correct)
            p, s = scores(O, R, np.float64)
            p32, s32 = scores(O, R, np.float32)
            row[label] = dict(psnr=p, ssim=s, psnr_f32=p32, ssim_f32=s32)
            if g is not None:
                row[label]["gain"] = g
        print(json.dumps(row))
    # skimage refuses planes smaller than the window; pgrf must too.
    try:
        z = np.zeros((6, 10, 4))
        structural_similarity(z, z, data_range=255, channel_axis=-1)
        print("# 6x10 planes: accepted (unexpected)")
    except ValueError as e:
        print(f"# 6x10 planes: ValueError: {str(e)[:60]}...")


if __name__ == "__main__":
    main()
