#!/usr/bin/env python3
"""`pgrf reduce` against astropy's ccdproc on virtual-sensor lights.

    cargo build -p pgrf-cli
    python3 tests/reference/reduce_ccdproc.py [path/to/pgrf]

For a Bayer (RGGB) and a monochrome virtual sensor (64x48, FITS) it runs

    pgrf simulate-sensor --fits --width 64 --height 48 --frames 8 \\
        --dark-exposures 0.02,0.05 --temperature -10 [--mono] -o vs
    pgrf calibrate --bias vs/bias --dark vs/dark --flat vs/flat \\
        --masters vs/masters -o vs/calib.safetensors
    pgrf simulate-sensor ... --frames 2 --stacks flat --seed 9 -o src
        (the 0.04 s frames of this second run, uniformly lit exposures of the
        same sensor, are the lights)
    pgrf reduce lights/*.fits --masters vs/masters --calib vs/calib.safetensors -o out

and reduces the same lights with ccdproc 2.5.1 from the same master files
(read by astropy; pgrf's FITS masters are 32-bit floats in 0-1, so x 65535):

    light_b = subtract_bias(light, bias)
    light_d = subtract_dark(light_b, subtract_bias(dark, bias),
                            dark_exposure=1 s, data_exposure=DARKSCL s, scale=True)
    flat_d  = the same two steps on the master flat (its dark scale computed
              here from the calibration's law, nearest dark in ratio)
    flat_n  = flat_d / its mean per 2x2 sub-lattice (one mean for mono)
    result  = flat_correct(light_d, flat_n, norm_value=1)

ccdproc scales a dark linearly by exposure; the calibration's law may be
sqrt(t), so the factor g(t)/g(t_d) that pgrf applied (the DARKSCL card) is
handed to ccdproc as the exposure ratio: the comparison checks the
arithmetic, and the factor itself is recomputed here from the law and
compared. ccdproc has no cosmetic correction: the defect map of the
calibration file is applied here with numpy (median of the non-defective
neighbours at step 2 on a Bayer mosaic, 1 on a monochrome sensor). The
calibration chose no dark offset for these sensors (checked).

Every pgrf output is opened with astropy (header cards and HISTORY read
back), and compared pixel by pixel: the largest |pgrf - ccdproc| / |ccdproc|
must stay below 1e-4. The numbers printed at the end are committed in
crates/cli/tests/reduce.rs, which reruns the pgrf commands and checks them.

Run on 2026-11-27 with astropy 8.0.2, ccdproc 2.5.1 and numpy 2.4.6, it printed:

    rggb: law sqrt, flat master_flat_0.04s.fits, 90 defective pixels
    rggb flat_8000e_0000.fits: ccdproc mean 12243.3063; (5, 7) 12499.606, (20, 30) 12263.737, (40, 60) 12051.853, (47, 63) 12166.584; max rel diff 1.45e-07; dark master_dark_0.05s.fits x0.894427
    rggb flat_8000e_0001.fits: ccdproc mean 12238.0593; (5, 7) 12526.686, (20, 30) 12142.403, (40, 60) 12059.836, (47, 63) 12142.854; max rel diff 1.58e-07; dark master_dark_0.05s.fits x0.894427
    mono: law sqrt, flat master_flat_0.04s.fits, 90 defective pixels
    mono flat_8000e_0000.fits: ccdproc mean 12243.2968; (5, 7) 12505.700, (20, 30) 12255.444, (40, 60) 12043.703, (47, 63) 12172.515; max rel diff 1.51e-07; dark master_dark_0.05s.fits x0.894427
    mono flat_8000e_0001.fits: ccdproc mean 12238.1422; (5, 7) 12532.793, (20, 30) 12134.192, (40, 60) 12051.681, (47, 63) 12148.774; max rel diff 1.56e-07; dark master_dark_0.05s.fits x0.894427
    largest relative difference pgrf - ccdproc: 1.58e-07 (tolerance 1e-4)
"""

import json
import struct
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import astropy.units as u
from astropy.io import fits
from astropy.nddata import CCDData
import ccdproc

ROOT = Path(__file__).resolve().parents[2]
PGRF = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "target" / "debug" / "pgrf"
PROBES = [(5, 7), (20, 30), (40, 60), (47, 63)]


def run(*args):
    r = subprocess.run([str(PGRF), *map(str, args)], capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"pgrf {' '.join(map(str, args))}: {r.stderr.strip()}")


def safetensors(path):
    """The tensors and JSON record of a pgrf calibration file."""
    b = path.read_bytes()
    n = struct.unpack("<Q", b[:8])[0]
    head = json.loads(b[8 : 8 + n])
    meta = json.loads(head.pop("__metadata__")["pgrf"])
    maps = {}
    for name, t in head.items():
        lo, hi = t["data_offsets"]
        maps[name] = np.frombuffer(b[8 + n + lo : 8 + n + hi], "<f4").reshape(t["shape"])
    return maps, meta


def defect_mask(maps, meta, h, w):
    """The calibration's defect map as a boolean image of the sensor."""
    d = maps["defects"]
    if meta["cfa"] == "mono":
        return d[0] != 0
    # Packed planes R, G1, B, G2 at the photosites the CFA puts them.
    pattern = meta["cfa"]
    spots = [i for i, c in enumerate(pattern) if c == "R"]
    greens = [i for i, c in enumerate(pattern) if c == "G"]
    spots = spots + [greens[0]] + [pattern.index("B")] + [greens[1]]
    out = np.zeros((h, w), bool)
    for p, k in enumerate(spots):
        out[k // 2 :: 2, k % 2 :: 2] = d[p] != 0
    return out


def cosmetic(img, bad, step):
    out = img.copy()
    h, w = img.shape
    for y, x in zip(*np.nonzero(bad)):
        near = [
            img[y + dy * step, x + dx * step]
            for dy in (-1, 0, 1)
            for dx in (-1, 0, 1)
            if (dy, dx) != (0, 0)
            and 0 <= y + dy * step < h
            and 0 <= x + dx * step < w
            and not bad[y + dy * step, x + dx * step]
        ]
        if near:
            out[y, x] = np.median(near)
    return out


def master(path):
    with fits.open(path) as f:
        return CCDData(f[0].data.astype(np.float64) * 65535.0, unit=u.adu), f[0].header


def g(law, t):
    return t if law == "linear" else np.sqrt(t)


def nearest(darks, t):
    return min(darks, key=lambda d: (abs(np.log(t / d[0])), -d[0]))


def case(work, mono):
    tag = "mono" if mono else "rggb"
    extra = ["--mono"] if mono else []
    vs, src, lights, out = (work / tag / n for n in ("vs", "src", "lights", "out"))
    (work / tag).mkdir()
    common = ["--fits", "--width", 64, "--height", 48, "--temperature", -10, *extra]
    run("simulate-sensor", *common, "--frames", 8, "--dark-exposures", "0.02,0.05", "-o", vs)
    run("calibrate", "--bias", vs / "bias", "--dark", vs / "dark", "--flat", vs / "flat",
        "--masters", vs / "masters", "-o", vs / "calib.safetensors")
    run("simulate-sensor", *common, "--frames", 2, "--stacks", "flat", "--seed", 9, "-o", src)
    lights.mkdir(parents=True)
    files = []
    for p in sorted((src / "flat").glob("flat_8000e_*.fits")):
        (lights / p.name).write_bytes(p.read_bytes())
        files.append(lights / p.name)
    run("reduce", *files, "--masters", vs / "masters", "--calib", vs / "calib.safetensors", "-o", out)

    maps, meta = safetensors(vs / "calib.safetensors")
    assert not meta["dark_offset"], "this comparison assumes no dark offset"
    law = meta["dark_law"]
    m = vs / "masters"
    bias, _ = master(m / "master_bias.fits")
    darks = []
    for p in sorted(m.glob("master_dark_*.fits")):
        d, hd = master(p)
        darks.append((hd["EXPTIME"], p.name, ccdproc.subtract_bias(d, bias)))
    flats = []
    for p in sorted(m.glob("master_flat_*.fits")):
        f, hf = master(p)
        flats.append((float(np.mean(f.data - bias.data)), hf["EXPTIME"], p.name, f))
    _, tf, flat_name, flat = max(flats, key=lambda f: f[0])
    td, _, dark_f = nearest(darks, tf)
    flat_b = ccdproc.subtract_bias(flat, bias)
    flat_d = ccdproc.subtract_dark(flat_b, dark_f, dark_exposure=1 * u.s,
                                   data_exposure=float(g(law, tf) / g(law, td)) * u.s, scale=True)
    fd = flat_d.data
    if mono:
        fn = fd / fd.mean()
    else:
        fn = fd.copy()
        for dy in (0, 1):
            for dx in (0, 1):
                fn[dy::2, dx::2] /= fd[dy::2, dx::2].mean()
    assert (fn > 0).all()
    h, w = fn.shape
    bad = defect_mask(maps, meta, h, w)
    worst, lines = 0.0, []
    for p in files:
        with fits.open(p) as f:
            light = CCDData(f[0].data.astype(np.float64), unit=u.adu)
            t = f[0].header["EXPTIME"]
        with fits.open(out / p.name) as f:
            f.verify("exception")
            hdr, got = f[0].header, f[0].data.astype(np.float64) * 65535.0
        td, dark_name, dark = nearest(darks, t)
        scale = g(law, t) / g(law, td)
        assert hdr["MDARK"] == dark_name and hdr["MBIAS"] == "master_bias.fits"
        assert hdr["MFLAT"] == flat_name and hdr["CALIB"] == "calib.safetensors"
        assert abs(hdr["DARKSCL"] - scale) < 1e-12 and hdr["DARKLAW"] == law
        assert abs(hdr["EXPTIME"] - t) < 1e-12 and hdr["IMAGETYP"] == "Light Frame"
        assert hdr["ROWORDER"] == meta["row_order"]
        assert hdr["NDEFECT"] == int(bad.sum())
        assert len(hdr["HISTORY"]) >= 4
        lb = ccdproc.subtract_bias(light, bias)
        ld = ccdproc.subtract_dark(lb, dark, dark_exposure=1 * u.s,
                                   data_exposure=float(hdr["DARKSCL"]) * u.s, scale=True)
        ref = ccdproc.flat_correct(ld, CCDData(fn, unit=u.dimensionless_unscaled), norm_value=1).data
        ref = cosmetic(ref, bad, 1 if mono else 2)
        rel = np.abs(got - ref) / np.abs(ref)
        worst = max(worst, float(rel.max()))
        probes = ", ".join(f"({y}, {x}) {ref[y, x]:.3f}" for y, x in PROBES)
        lines.append(f"{tag} {p.name}: ccdproc mean {ref.mean():.4f}; {probes}; "
                     f"max rel diff {rel.max():.2e}; dark {dark_name} x{scale:.6f}")
    print(f"{tag}: law {law}, flat {flat_name}, {int(bad.sum())} defective pixels")
    for line in lines:
        print(line)
    return worst


def main():
    with tempfile.TemporaryDirectory() as d:
        worst = max(case(Path(d), False), case(Path(d), True))
    print(f"largest relative difference pgrf - ccdproc: {worst:.2e} (tolerance 1e-4)")
    if not worst < 1e-4:
        sys.exit(1)


if __name__ == "__main__":
    main()
