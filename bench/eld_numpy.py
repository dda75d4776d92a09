#!/usr/bin/env python3
"""ELD's physics-based noise model (Wei et al., CVPR 2020, "A Physics-based
Noise Formation Model for Extreme Low-light Raw Denoising") in numpy, written
for pgrf's benchmarks: the peer that `pgrf.synth(model="eld")` is timed and
checked against. Single-threaded numpy and scipy, as ELD runs it.

What ELD does, step by step, and what here mirrors it
-----------------------------------------------------
ELD's noise maker is `noise.NoiseModel` (repository Vandermode/ELD, file
noise.py): `_sample_params()` draws one capture's parameters and
`NoiseModelBase.__call__(y, params)` adds noise to a packed clean image y in
[0, 1] (RGBG planes, `RawPacker.pack_raw_bayer`). The noise.py read for
this (Vandermode/ELD, commit 39846c7) implements only the baselines (g, P+g,
p+g); the full model ("PGBRU": shot, Tukey-lambda read, colour bias, row,
quantisation) below follows the extended `NoiseModel` found in ELD-derived
code, which keeps those two functions and adds the components, drawing from
the keys of ELD's released `camera_params/release/SonyA7S2_params.npy`
(G_shape, color_bias, Profile-1 g_scale / G_scale / R_scale, Kmin, Kmax).

`sample_params(fits, rng)`  <->  `NoiseModel._sample_params()`
  * saturation_level = 16383 - 800 (ELD uses this DN range for every camera;
    its fits are expressed on it), Q_step = 1 DN.
  * G_shape = one of the calibration's Tukey-lambda shapes, uniformly
    (`np.random.choice(camera_params['G_shape'])`).
  * color_bias = one row of `camera_params['color_bias']`, uniformly and
    independently of the shape (`np.random.randint`).
  * ln K ~ U(ln Kmin, ln Kmax): K log-uniform over the camera's gain range.
  * for each scale s in (g_scale, G_scale, R_scale):
    ln s = slope_s * ln K + bias_s + sigma_s * N(0, 1)   (ELD's regressions,
    `camera_params['Profile-1'][s]`).
  * ratio ~ U(100, 300).

`add_noise(y, p, rng)`  <->  `NoiseModelBase.__call__(y, params)`
  1. y = y * saturation_level / ratio          (DN of the short exposure)
  2. P: z = Poisson(y / K) * K                 (`np.random.poisson`, shot noise)
  3. G: z += TukeyLambda(G_shape, loc 0, scale G_scale), i.i.d. per pixel
        (`scipy.stats.tukeylambda.rvs`, read noise);
     g (Gaussian baseline instead): z += g_scale * N(0, 1) per pixel
  4. B: z += color_bias[c] per plane c         (`add_color_bias`)
  5. R: z += R_scale * N(0, 1), one draw per sensor row
        (`add_banding_noise`; ELD adds it on the unpacked mosaic, so planes R
        and G1 take the draws of the even sensor rows, B and G2 of the odd
        ones; done here on the packed planes directly, same values, without
        the unpack/pack copies)
  6. U: z += U(-Q_step/2, Q_step/2)            (`np.random.uniform`; ELD's call
        has no `size`, so it draws ONE offset for the whole image: that is
        `quantisation="eld"`, the default; `quantisation="pixel"` draws one
        per pixel, the textbook model and pgrf's)
  7. z = z * ratio / saturation_level          (brightened: ELD's noise maker
        returns the noisy short exposure multiplied back by the ratio)
  then ELD's dataset (`SynDataset.__getitem__`) clips to [0, 1]:
  `brightened = np.clip(z, 0, 1)`, which `eld_noisy()` returns.

Random numbers: ELD calls numpy's legacy global sampler (`np.random.*`,
a RandomState); `rng` here is a `np.random.RandomState` by default (same
algorithms, seedable per call) or any `np.random.Generator`.

Parameters for a fixed ISO (`params_at_iso`) come from pgrf's built-in
profile file crates/noise/profiles/sony-a7s2.json (ELD's SonyA7S2 fits and
PMN's per-ISO A7S2 table, read as plain JSON: no pgrf import), so the same
capture can be given to both implementations.
"""
import json
import math
import os
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

ELD_SATURATION = 16383 - 800
PROFILE_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "crates", "noise", "profiles")


@dataclass
class EldParams:
    """One capture's parameters, the tuple ELD's `_sample_params` returns
    (K, color_bias, g_scale, G_scale, G_shape, R_scale, Q_step,
    saturation_level, ratio); noise values in DN on `saturation_level`."""
    K: float
    G_shape: float
    G_scale: float
    g_scale: float
    R_scale: float
    color_bias: np.ndarray = field(default_factory=lambda: np.zeros(4, np.float32))
    Q_step: float = 1.0
    saturation_level: float = float(ELD_SATURATION)
    ratio: float = 100.0


def load_fits(profile="sony-a7s2"):
    """ELD's parameter fits for a camera, in the keys of ELD's
    `<camera>_params.npy` (Kmin, Kmax, G_shape, color_bias, Profile-1 ->
    g_scale / G_scale / R_scale -> slope, bias, sigma), plus the profile's
    per-ISO table and DN range. `profile`: a name of pgrf's built-in profiles
    or a path to such a JSON file."""
    path = profile if os.path.exists(profile) else os.path.join(PROFILE_DIR, f"{profile}.json")
    with open(path) as f:
        p = json.load(f)
    e = p["eld"]
    return {
        "Kmin": p["k_min"],
        "Kmax": p["k_max"],
        "G_shape": np.asarray(e["tukey_shapes"], np.float64),
        "color_bias": np.asarray(e["color_bias"] or [[0.0] * 4], np.float64),
        "Profile-1": {
            "G_scale": e["tukey_scale"],
            "g_scale": e["gauss_scale"],
            "R_scale": e["row_scale"],
        },
        "per_iso": p.get("per_iso", []),
        "dn_range": p["dn_range"],
        "k_per_iso": p.get("k_per_iso"),
    }


def sample_params(fits, rng, ratio=None):
    """ELD's `NoiseModel._sample_params()` for one camera (see the module
    docstring). `ratio`: fixed exposure ratio instead of ELD's U(100, 300)."""
    G_shape = float(rng.choice(fits["G_shape"]))
    cb = fits["color_bias"]
    color_bias = cb[rng.randint(0, cb.shape[0]) if hasattr(rng, "randint") else rng.integers(0, cb.shape[0])]
    log_K = rng.uniform(math.log(fits["Kmin"]), math.log(fits["Kmax"]))
    prof = fits["Profile-1"]

    def scale(name):
        f = prof[name]
        return math.exp(rng.standard_normal() * f["sigma"] + f["slope"] * log_K + f["bias"])

    g_scale = scale("g_scale")
    G_scale = scale("G_scale")
    R_scale = scale("R_scale")
    r = rng.uniform(100, 300)
    return EldParams(
        K=math.exp(log_K), G_shape=G_shape, G_scale=G_scale, g_scale=g_scale, R_scale=R_scale,
        color_bias=np.asarray(color_bias, np.float32), Q_step=1.0,
        saturation_level=float(ELD_SATURATION), ratio=float(ratio if ratio is not None else r))


def params_at_iso(fits, iso, ratio=100.0):
    """Point parameters at `iso` from the profile's per-ISO table (linear in
    log ISO between entries, K = k_per_iso x ISO), on the profile's own DN
    range, with the measured black-level error as the colour bias on every
    plane: the capture `pgrf.synth(..., iso=iso, model="eld")` makes from
    pgrf's built-in profile (crates/noise/src/params.rs, params_at_iso), so
    both implementations can be run on the same parameters."""
    t = fits["per_iso"]
    if not t:
        raise ValueError("profile has no per-ISO table")
    if not t[0]["iso"] <= iso <= t[-1]["iso"]:
        raise ValueError(f"ISO {iso} outside {t[0]['iso']}..{t[-1]['iso']}")
    j = next(i for i, r in enumerate(t) if r["iso"] >= iso)
    a, b = (t[j], t[j]) if t[j]["iso"] == iso else (t[j - 1], t[j])
    w = 0.0 if a["iso"] == b["iso"] else (math.log(iso) - math.log(a["iso"])) / (math.log(b["iso"]) - math.log(a["iso"]))

    def lerp(key):
        return a[key] + w * (b[key] - a[key])

    k = fits["k_per_iso"] * iso if fits.get("k_per_iso") else lerp("k")
    ble = lerp("black_level_error")
    return EldParams(
        K=k, G_shape=lerp("tukey_lambda"), G_scale=lerp("sigma_tukey"), g_scale=lerp("sigma_gauss"),
        R_scale=lerp("sigma_row"), color_bias=np.full(4, ble, np.float32), Q_step=1.0,
        saturation_level=float(fits["dn_range"]), ratio=float(ratio))


def add_noise(y, p, rng, model="PGBRU", quantisation="eld"):
    """ELD's `NoiseModelBase.__call__(y, params)`: the noisy image brightened
    by the ratio (not clipped). `y`: float32 (4, h, w) packed clean in
    [0, 1], planes R, G1, B, G2 (R, G1 on even sensor rows). `model`: ELD's
    component letters, P (Poisson shot), G (Tukey read) or g (Gaussian read),
    B (colour bias), R (row), U (quantisation)."""
    if y.ndim != 3 or y.shape[0] != 4:
        raise ValueError(f"expected a packed (4, h, w) image, got {y.shape}")
    sat, ratio = p.saturation_level, p.ratio
    y = y * np.float32(sat / ratio)                                  # 1
    if "P" in model:                                                 # 2
        z = rng.poisson(y / np.float32(p.K)).astype(np.float32) * np.float32(p.K)
    else:
        z = y.copy()
    if "G" in model:                                                 # 3
        z += stats.tukeylambda.rvs(p.G_shape, loc=0, scale=p.G_scale, size=y.shape,
                                   random_state=rng).astype(np.float32)
    elif "g" in model:
        z += rng.standard_normal(y.shape).astype(np.float32) * np.float32(max(p.g_scale, 1e-10))
    if "B" in model:                                                 # 4
        z += np.asarray(p.color_bias, np.float32).reshape(4, 1, 1)
    if "R" in model:                                                 # 5
        rows = (rng.standard_normal(2 * y.shape[1]) * p.R_scale).astype(np.float32)
        z[0:2] += rows[0::2][None, :, None]
        z[2:4] += rows[1::2][None, :, None]
    if "U" in model:                                                 # 6
        q = p.Q_step
        if quantisation == "eld":
            z += np.float32(rng.uniform(-0.5 * q, 0.5 * q))
        elif quantisation == "pixel":
            z += (rng.uniform(-0.5 * q, 0.5 * q, size=y.shape)).astype(np.float32)
        else:
            raise ValueError(f"quantisation '{quantisation}' (eld or pixel)")
    z *= np.float32(ratio / sat)                                     # 7
    return z


def eld_noisy(clean, p, rng, model="PGBRU", quantisation="eld"):
    """The network input ELD trains on: `add_noise` clipped to [0, 1] as
    ELD's `SynDataset` does. Same layout as `pgrf.synth(...).brightened`."""
    z = add_noise(clean, p, rng, model=model, quantisation=quantisation)
    np.clip(z, 0.0, 1.0, out=z)
    return z


def expected_moments(level, p, quantisation="eld"):
    """Analytic mean and variance (brightened units, before clipping) of a
    flat input `level` under the full model: shot K*y, Tukey read
    G_scale^2 Var(TL(G_shape)), row R_scale^2, quantisation Q^2/12 (between
    images for "eld", within for "pixel"); mean y + bias per plane."""
    y = level * p.saturation_level / p.ratio
    var = p.K * y + p.G_scale ** 2 * float(stats.tukeylambda.var(p.G_shape)) + p.R_scale ** 2
    if quantisation == "pixel":
        var += p.Q_step ** 2 / 12
    s = p.ratio / p.saturation_level
    return (y + np.asarray(p.color_bias, np.float64)) * s, var * s * s


def _selftest():
    fits = load_fits()
    rng = np.random.RandomState(0)
    p = params_at_iso(fits, 1600, ratio=100.0)
    y = np.full((4, 400, 500), 0.3, np.float32)
    z = add_noise(y, p, rng, quantisation="pixel")
    m, v = expected_moments(0.3, p, "pixel")
    print("ISO 1600 point:", p)
    for c in range(4):
        print(f"plane {c}: mean {z[c].mean():.5f} (expect {m[c]:.5f})  var {z[c].var():.3e} (expect {v:.3e})")
    q = sample_params(fits, np.random.RandomState(1))
    print("ELD draw:", q)
    out = eld_noisy(y, q, rng)
    print("brightened", out.shape, out.dtype, float(out.min()), float(out.max()))


if __name__ == "__main__":
    _selftest()
