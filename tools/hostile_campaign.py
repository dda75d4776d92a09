#!/usr/bin/env python3
"""Issue 17's mutation campaign, repeatable: mutated RAW files through
pgrf info / preview / convert / enhance under a 2 GB address-space limit.

    tools/hostile_campaign.py [--pgrf target/release/pgrf] [--per-class 12]
                              [--seed 17] [--work DIR] [--keep-failures DIR]

Inputs are the real RAW files of ../shared/data/raw (the 550D DNG, the
Canon 6D lossy DNG, the Kodak KDC, the headerless DSLR crop converted to a
DNG by pgrf) and a pgrf chart DNG. Each is mutated in five classes, with a
seeded generator (the same seed gives the same files):

    truncate   cut at a random point (1 % .. 99 % of the file)
    flip       1, 8 or 64 random bytes XORed with random non-zero values
    zero       a random window of 16 .. 4096 bytes set to zero
    field      one TIFF IFD entry's count or value set to 0, 1, 2^31 - 1,
               2^32 - 1, the file's length or a random value (TIFF-based
               inputs; others get a flip instead)
    append     1 KiB .. 1 MiB of random bytes appended

Every mutated file goes through `info`, `preview --half`, `convert` and
(for files under 2 MB) `enhance --model builtin:spc --ratio 20 --tile 256`.
A run passes when it exits 0, or exits 1 with exactly one non-empty stderr
line starting with `pgrf: error: `. Anything else is a failure: an abort
(134, "memory allocation failed" under the limit), an internal error (101),
a signal, a time-out (120 s), or a message that is not one line. The peak
resident memory of any run is reported (RUSAGE_CHILDREN's ru_maxrss).

Issue 37's classes (`--classes`, comma-separated; default all), each
made by the campaign itself and each case a refusal or a success that is
known to be right; an exit 0 where the input contradicts itself counts as
a failure ("accepted": garbage or an unloadable file written):

    dngfield   targeted contradictions in a chart DNG's tiles (TileByteCounts
               cut to 0, 1, 100 or a random share, TileWidth and TileLength
               set to 0, 16, 65535 or a random value) and in the 550D's
               uncompressed strip (BitsPerSample 8..16 but 14), through
               info / preview / convert / enhance: each must be refused
    saturate   FITS files (a converted chart) with SATURATE or DATAMAX below
               the largest sample (refused unless --white; with --white:
               ok) and at or above it (ok)
    counts     absurd values of the flags issue 37 bounded: --sampler
               euler:-N, --ratio / --target-exposure outside 1..10000
               (enhance, synth, eval), make-dataset --scenes 1e9, train
               --steps 0, enhance -o X.safetensors; enhance --samples 1e5 and
               1e9, train --val-pairs / --workers / --batch 1e9, --workers 0,
               --steps 2^64 - 1; and seeds up to 2^64 - 1 (must be accepted)
    fitssize   sparse FITS frames through info / preview / convert / enhance:
               720 MP (header alone) and 650 MP refused; 500 MP of 8-bit
               samples, 100 MP Bayer and mono decoded or refused for memory
               with the figures, never an abort
    collide    output/input collisions for every command and output flag:
               an output that is an input (the RAW, the model, the config,
               a profile, a calibration frame), one inside an input folder
               (a stack, --root, --data, --val), an output folder holding
               an input, two outputs on one path (also the default
               NAME_worst.png beside --csv): each must be refused, and every
               file of the case's folder left byte for byte ("overwritten"
               or "wrote" otherwise)
    resume     train a tiny denoiser, then resume it after it finished
               (must say "already finished" and leave the file byte for
               byte), lose its weight file and resume (rewritten from the
               checkpoint), resume with a smaller --steps (refused); every
               weight file left must load in enhance; export-weights of a
               record its tensors do not fit (refused)

The mutation classes above are `mutate`; `--classes mutate` runs them alone.

Ends with a table per command and class and exits 1 if anything failed.
Needs Python 3 only; pgrf must be built (release).
"""

import argparse
import os
import random
import resource
import shutil
import struct
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

LIMIT = 2 << 30  # bytes of address space per run
TIMEOUT = 120


def tiff_entries(b):
    """(offset of entry, tag, type, count) of the IFD chain from the header,
    plus the entries of SubIFD/EXIF IFDs; empty if not TIFF."""
    if b[:2] == b"II":
        e = "<"
    elif b[:2] == b"MM":
        e = ">"
    else:
        return []
    if len(b) < 8:
        return []
    out, seen = [], set()
    todo = [struct.unpack(e + "I", b[4:8])[0]]
    while todo and len(seen) < 64:
        off = todo.pop()
        if off in seen or off + 2 > len(b):
            continue
        seen.add(off)
        n = struct.unpack(e + "H", b[off : off + 2])[0]
        if off + 2 + 12 * n + 4 > len(b) or n > 4096:
            continue
        for i in range(n):
            at = off + 2 + 12 * i
            tag, typ, count = struct.unpack(e + "HHI", b[at : at + 8])
            out.append((at, tag, typ, count, e))
            if tag in (330, 34665) and count >= 1 and typ in (4, 13):
                if count == 1:
                    todo.append(struct.unpack(e + "I", b[at + 8 : at + 12])[0])
                else:
                    p = struct.unpack(e + "I", b[at + 8 : at + 12])[0]
                    for k in range(min(count, 16)):
                        if p + 4 * k + 4 <= len(b):
                            todo.append(struct.unpack(e + "I", b[p + 4 * k : p + 4 * k + 4])[0])
        todo.append(struct.unpack(e + "I", b[off + 2 + 12 * n : off + 6 + 12 * n])[0])
    return out


def mutate(kind, data, rng):
    b = bytearray(data)
    if kind == "truncate":
        return bytes(b[: max(1, int(len(b) * rng.uniform(0.01, 0.99)))])
    if kind == "flip" or (kind == "field" and not tiff_entries(data)):
        for _ in range(rng.choice([1, 8, 64])):
            i = rng.randrange(len(b))
            b[i] ^= rng.randrange(1, 256)
        return bytes(b)
    if kind == "zero":
        n = rng.randint(16, 4096)
        i = rng.randrange(max(1, len(b) - n))
        b[i : i + n] = bytes(min(n, len(b) - i))
        return bytes(b)
    if kind == "field":
        at, _tag, _typ, _count, e = rng.choice(tiff_entries(data))
        value = rng.choice([0, 1, 2**31 - 1, 2**32 - 1, len(b), rng.randrange(2**32)])
        where = at + rng.choice([4, 8])  # the count, or the value/offset
        b[where : where + 4] = struct.pack(e + "I", value)
        return bytes(b)
    if kind == "append":
        return bytes(b) + rng.randbytes(rng.randint(1024, 1 << 20))
    raise ValueError(kind)


def limit():
    resource.setrlimit(resource.RLIMIT_AS, (LIMIT, LIMIT))


def run(args):
    """(exit code or -signal, stderr, peak RSS in MiB, seconds)."""
    t = time.time()
    p = subprocess.Popen(
        args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, preexec_fn=limit
    )
    try:
        _, err = p.communicate(timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        p.kill()
        _, err = p.communicate()
        return "timeout", err.decode(errors="replace"), 0, time.time() - t
    # RUSAGE_CHILDREN's ru_maxrss is the largest peak of any child reaped
    # so far: the campaign's peak, which is what "no run over 2 GB" needs.
    rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    return p.returncode, err.decode(errors="replace"), rss, time.time() - t


def verdict(code, err):
    lines = [l for l in err.splitlines() if l.strip()]
    if code == 0:
        return "ok"
    if code == 1 and len(lines) == 1 and lines[0].startswith("pgrf: error: "):
        return "refused"
    if code == "timeout":
        return "timeout"
    if code == 134 or "memory allocation" in err:
        return "abort"
    if code == 101:
        return "internal"
    if isinstance(code, int) and code < 0:
        return f"signal {-code}"
    return f"exit {code}, {len(lines)} lines"


# ----------------------------------------------------------- issue 37's classes


def ifd0_entries(b):
    """(entry offset, tag, type, count) of IFD0 of a little-endian TIFF."""
    off = struct.unpack("<I", b[4:8])[0]
    n = struct.unpack("<H", b[off : off + 2])[0]
    return [(off + 2 + 12 * i,) + struct.unpack("<HHI", b[off + 2 + 12 * i : off + 10 + 12 * i])
            for i in range(n)]


def set_value(b, tag, value):
    """`b` with the one inline value of `tag` in IFD0 set, keeping its type."""
    b = bytearray(b)
    for at, t, typ, count in ifd0_entries(b):
        if t == tag:
            assert count == 1, (tag, count)
            if typ == 3:
                b[at + 8 : at + 10] = struct.pack("<H", value)
            else:
                b[at + 8 : at + 12] = struct.pack("<I", value)
            return bytes(b)
    raise KeyError(tag)


def value_of(b, tag):
    for at, t, typ, _count in ifd0_entries(b):
        if t == tag:
            return struct.unpack("<H" if typ == 3 else "<I", b[at + 8 : at + (10 if typ == 3 else 12)])[0]
    raise KeyError(tag)


def through_readers(pgrf, f, out, extra=()):
    """The commands of the mutation classes on file `f`, outputs in `out`."""
    cmds = {
        "info": [pgrf, "info", str(f), *extra],
        "preview": [pgrf, "preview", str(f), "--half", "-o", str(out / "p.png"), *extra],
        "convert": [pgrf, "convert", str(f), "-o", str(out / "c.dng"), *extra],
        # The built-in SPC is noise-aware: told a noise, so that a frame with
        # none to estimate (a smooth synthetic one) tests the file, not that.
        "enhance": [pgrf, "enhance", str(f), "--model", "builtin:spc", "--ratio", "20",
                    "--noise", "K=1,read=4", "--tile", "256", "-o", str(out / "e.dng"), *extra],
    }
    return cmds


def dngfield_cases(work, pgrf, shared, rng, n):
    """(name, file, expect) of the targeted DNG contradictions."""
    chart = (work / "chart.dng").read_bytes()
    count = value_of(chart, 325)
    cases = []
    for v in [0, 1, 100, rng.randrange(2, count)] + [rng.randrange(2, count) for _ in range(n)]:
        cases.append((f"tilebytes_{v}", set_value(chart, 325, v)))
    for tag, name in [(322, "tilewidth"), (323, "tilelength")]:
        for v in [0, 16, 65535, rng.choice([32, 48, 128, 240, 272, 4096])]:
            cases.append((f"{name}_{v}", set_value(chart, tag, v)))
    src = shared / "canon550d_colorchart.dng"
    if not src.exists():
        src = Path(__file__).resolve().parent.parent / "crates/cli/assets/canon550d_colorchart.dng"
    b550 = src.read_bytes()
    for bits in [8, 10, 12, 13, 15, 16]:
        cases.append((f"550d_bits{bits}", set_value(b550, 258, bits)))
    return [(name, data, "refused") for name, data in cases]


def fits_with(fits, cards, drop=()):
    """A FITS file's bytes with the header cards `cards` ("KEY= value")
    replacing any of the same keys, and the keys `drop` left out."""
    end = next(i for i in range(len(fits) // 80) if fits[80 * i : 80 * i + 8] == b"END     ")
    data_at = -(-80 * (end + 1) // 2880) * 2880
    keys = {c.split("=")[0].strip() for c in cards} | set(drop)
    kept = [fits[80 * i : 80 * i + 80] for i in range(end)
            if fits[80 * i : 80 * i + 8].decode().strip() not in keys]
    head = b"".join(kept + [c.ljust(80).encode() for c in cards] + [b"END".ljust(80)])
    assert len(head) <= data_at, "no room in the header block"
    return head.ljust(data_at, b" ") + fits[data_at:], data_at


def saturate_cases(work, pgrf, rng):
    fits = work / "chart.fits"
    subprocess.run([pgrf, "convert", str(work / "chart.dng"), "-o", str(fits)], check=True,
                   stderr=subprocess.DEVNULL)
    raw = fits.read_bytes()
    _, data_at = fits_with(raw, [])
    n = 256 * 192
    vals = [struct.unpack(">h", raw[data_at + 2 * i : data_at + 2 * i + 2])[0] + 32768 for i in range(n)]
    top = max(vals)
    cases = []
    for key in ["SATURATE", "DATAMAX"]:
        for level in [1, top // 2, top - 1, rng.randrange(1, top)]:
            b, _ = fits_with(raw, [f"{key:<8}= {level:>20}"], drop=["SATURATE"])
            cases.append((f"{key.lower()}_{level}", b, "refused", ()))
            cases.append((f"{key.lower()}_{level}_white", b, "ok", ("--white", "65535")))
        for level in [top, top + 1, 65534]:
            b, _ = fits_with(raw, [f"{key:<8}= {level:>20}"], drop=["SATURATE"])
            cases.append((f"{key.lower()}_{level}", b, "ok", ()))
    return cases


def counts_cases(work, pgrf):
    """(name, argv, expect): flags issue 37 bounded."""
    c, out = str(work / "chart.dng"), work / "out"
    cases = []
    for sampler in ["euler:-5", "euler--5", "euler:0", "euler:-1", "euler:10001"]:
        cases.append((f"sampler_{sampler}", [pgrf, "enhance", c, "--model", "builtin:pgrf", "--sampler",
                                             sampler, "--ratio", "20", "-o", str(out / "e.dng")], "refused"))
    for r in ["1e30", "1e-30", "0", "-1", "0.5", "10001", "nan", "inf"]:
        cases.append((f"enhance_ratio_{r}", [pgrf, "enhance", c, "--model", "builtin:spc", "--ratio", r,
                                             "-o", str(out / "e.dng")], "refused"))
        cases.append((f"synth_ratio_{r}", [pgrf, "synth", c, "--profile", "sony-a7s2", "--ratio", r,
                                           "-o", str(out / "s.dng")], "refused"))
        cases.append((f"eval_ratio_{r}", [pgrf, "eval", "--protocol", "synthetic", "--root", c, "--model",
                                          "builtin:spc", "--iso", "1600", "--ratio", r], "refused"))
    for t in ["1e30", "1e-12"]:
        cases.append((f"target_exposure_{t}", [pgrf, "enhance", c, "--model", "builtin:spc",
                                               "--target-exposure", t, "-o", str(out / "e.dng")], "refused"))
    for scenes in ["1000000000", "4294967295"]:
        cases.append((f"scenes_{scenes}", [pgrf, "make-dataset", "--layout", "eld", "-o", str(out / "ds"),
                                           "--scenes", scenes], "refused"))
    for o in ["model.safetensors", "x.png", "x.toml"]:
        cases.append((f"enhance_o_{o}", [pgrf, "enhance", c, "--model", "builtin:spc", "--ratio", "20",
                                         "-o", str(out / o)], "refused"))
    tiny = ["train", "denoiser", "--width", "4", "--patch", "32", "--val-pairs", "1", "--data",
            "procedural", "--iso", "1600", "--quiet"]
    cases.append(("steps_0", [pgrf, *tiny, "--steps", "0", "-o", str(out / "z.safetensors")], "refused"))
    for seed in [str(2**63), str(2**64 - 1)]:
        cases.append((f"seed_{seed}", [pgrf, *tiny, "--steps", "1", "--seed", seed, "-o",
                                       str(out / "s.safetensors")], "ok"))
    cases.append(("seed_2^64", [pgrf, *tiny, "--steps", "1", "--seed", str(2**64), "-o",
                                str(out / "s.safetensors")], "refused"))
    # Memory: counts whose buffers or threads no machine has.
    for n in ["100000", "1000000000"]:
        cases.append((f"samples_{n}", [pgrf, "enhance", c, "--model", "builtin:pgrf", "--ratio", "20",
                                       "--noise", "K=1,read=4", "--samples", n, "-o", str(out / "e.dng")],
                      "refused"))
    for flag, n in [("--val-pairs", "1000000000"), ("--workers", "1000000000"), ("--workers", "0"),
                    ("--batch", "1000000000"), ("--steps", str(2**64 - 1))]:
        args = [a for a in tiny if a not in ("--val-pairs", "1")] if flag == "--val-pairs" else tiny
        steps = [] if flag == "--steps" else ["--steps", "1"]
        cases.append((f"train{flag}_{n}", [pgrf, *args, *steps, flag, n, "-o",
                                            str(out / "v.safetensors")], "refused"))
    return cases


def sparse_fits(path, w, h, bitpix=8, bayer=False):
    """A FITS file of w x h zero samples written sparse (no disk for data)."""
    cards = ["SIMPLE  = %20s" % "T", "BITPIX  = %20d" % bitpix, "NAXIS   = %20d" % 2,
             "NAXIS1  = %20d" % w, "NAXIS2  = %20d" % h]
    if bayer:
        cards.append("BAYERPAT= 'RGGB'")
    cards.append("END")
    head = "".join(c.ljust(80) for c in cards)
    head = head.ljust(-(-len(head) // 2880) * 2880).encode()
    total = -(-(len(head) + w * h * abs(bitpix) // 8) // 2880) * 2880
    with open(path, "wb") as f:
        f.write(head)
        f.seek(total - 1)
        f.write(b"\0")


def fitssize_cases(work):
    """(name, file, expect) of FITS frames at and past the sizes pgrf takes:
    past 600 MP (refused from the header alone, data or not), 500 MP of
    8-bit samples (decoded or refused for memory, never an abort), 100 MP
    Bayer and mono. `None`: ok or refused, whichever the memory allows."""
    d = work / "fitssize"
    d.mkdir(exist_ok=True)
    cases = []
    for name, w, h, bits, bayer, expect in [
        ("720mp_header_only", 30000, 24000, 8, False, "refused"),
        ("650mp", 26000, 25000, 8, False, "refused"),
        ("500mp_8bit", 25000, 20000, 8, False, None),
        ("100mp_bayer16", 10000, 10000, 16, True, None),
        ("100mp_mono8", 10000, 10000, 8, False, None),
    ]:
        f = d / f"{name}.fits"
        sparse_fits(f, w, h, bits, bayer)
        if name.endswith("header_only"):
            with open(f, "r+b") as fh:
                fh.truncate(2880)
        cases.append((name, f, expect))
    return cases


def loads(pgrf, model, work):
    code, err, _, _ = run([pgrf, "enhance", str(work / "chart.dng"), "--model", str(model), "--ratio", "20",
                           "-o", str(work / "out" / "load.dng")])
    return code == 0, err


def resume_class(work, pgrf, trials, record):
    """Resume-after-finish trials; `record(case, verdict, detail)`."""
    out = work / "out"
    base = ["train", "denoiser", "--width", "4", "--patch", "32", "--val-pairs", "1", "--data",
            "procedural", "--iso", "1600", "--quiet"]
    for k in range(trials):
        m = out / f"r{k}.safetensors"
        args = [pgrf, *base, "--seed", str(k), "-o", str(m)]
        code, err, _, _ = run(args + ["--steps", "2"])
        if code != 0:
            record("first run", f"exit {code}", err)
            continue
        first = m.read_bytes()
        code, err, _, _ = run(args + ["--steps", "2", "--resume"])
        ok = code == 0 and m.read_bytes() == first
        record("resume finished", "ok" if ok else "accepted", err if not ok else "")
        good, err = loads(pgrf, m, work)
        record("finished file loads", "ok" if good else "unloadable", err)
        m.unlink()
        code, err, _, _ = run(args + ["--steps", "2", "--resume"])
        good, err2 = loads(pgrf, m, work) if code == 0 else (False, err)
        record("lost file rewritten", "ok" if good else "unloadable", err2)
        code, err, _, _ = run(args + ["--steps", "1", "--resume"])
        record("resume past --steps", verdict(code, err), err)
    # A record its tensors do not fit.
    m = out / "r0.safetensors"
    if m.exists():
        b = m.read_bytes()
        n = struct.unpack("<Q", b[:8])[0]
        import json
        head = json.loads(b[8 : 8 + n])
        rec = json.loads(head["__metadata__"]["pgrf"])
        for width in [100000000, 8]:
            rec["config"]["width"] = width
            head["__metadata__"]["pgrf"] = json.dumps(rec)
            hb = json.dumps(head).encode()
            hb += b" " * (-len(hb) % 8)
            bad = out / f"w{width}.safetensors"
            bad.write_bytes(struct.pack("<Q", len(hb)) + hb + b[8 + n :])
            code, err, _, _ = run([pgrf, "export-weights", str(bad), "-o", str(out / "x.pth")])
            v = verdict(code, err)
            record(f"export width {width}", "accepted" if v == "ok" else v, err)


def collide_cases(work, pgrf):
    """(name, argv) of output/input collisions, every command and output
    flag: an output that is an input file, sits inside an input folder,
    holds one (folders), or shares a path with another output. Every case
    must be refused with every input left byte for byte."""
    d = work / "collide"
    if d.exists():
        shutil.rmtree(d)
    d.mkdir()
    c = d / "c.dng"
    shutil.copy(work / "chart.dng", c)
    for stack in ["bias", "flat", "raws"]:
        (d / stack).mkdir()
        shutil.copy(work / "chart.dng", d / stack / "f1.dng")
    w, t, pj = d / "w.safetensors", d / "t.toml", d / "p.json"
    w.write_bytes(b"weights stand-in")
    t.write_text("steps = 1\n")
    pj.write_text("{}")
    bias, flat, raws = d / "bias", d / "flat", d / "raws"
    S = str
    ev = [pgrf, "eval", "--protocol", "synthetic", "--root", S(c), "--model", "builtin:spc",
          "--ratio", "100", "--iso", "1600"]
    tr = [pgrf, "train", "spc", "--config", S(t)]
    ca = [pgrf, "calibrate", "--bias", S(bias), "--flat", S(flat)]
    en = [pgrf, "enhance", "--model", "builtin:spc", "--ratio", "20", "--noise", "K=1,read=4"]
    sy = [pgrf, "synth", S(c), "--profile", "sony-a7s2"]
    cases = [
        ("preview_o_input", [pgrf, "preview", S(c), "-o", S(c)]),
        ("convert_o_input", [pgrf, "convert", S(c), "-o", S(c)]),
        ("synth_o_input", [*sy, "-o", S(c)]),
        ("synth_png_input", [*sy, "-o", S(d / "s.dng"), "--png", S(c)]),
        ("synth_o_png", [*sy, "-o", S(d / "s.dng"), "--png", S(d / "s.dng")]),
        ("synth_o_profile", [pgrf, "synth", S(c), "--profile", S(pj), "-o", S(pj)]),
        ("simulate_o_file", [pgrf, "simulate-sensor", "-o", S(c)]),
        ("make_dataset_o_file", [pgrf, "make-dataset", "--layout", "eld", "-o", S(c)]),
        ("calibrate_o_frame", [*ca, "-o", S(bias / "f1.dng")]),
        ("calibrate_o_in_stack", [*ca, "-o", S(bias / "cal.safetensors")]),
        ("calibrate_report_in_stack", [*ca, "-o", S(d / "cal.st"), "--report", S(flat / "r")]),
        ("calibrate_masters_in_stack", [*ca, "-o", S(d / "cal.st"), "--masters", S(bias / "m")]),
        ("calibrate_masters_is_stack", [*ca, "-o", S(d / "cal.st"), "--masters", S(bias)]),
        ("calibrate_report_holds_stack", [*ca, "-o", S(d / "cal.st"), "--report", S(d)]),
        ("calibrate_darktable_frame", [*ca, "-o", S(d / "cal.st"), "--darktable-into", S(flat / "f1.dng")]),
        ("calibrate_o_darktable", [*ca, "-o", S(d / "cal.st"), "--darktable-into", S(d / "cal.st")]),
        ("train_o_config", [*tr, "-o", S(t)]),
        ("train_log_config", [*tr, "-o", S(d / "m.st"), "--log", S(t)]),
        ("train_checkpoint_config", [*tr, "-o", S(d / "m.st"), "--checkpoint", S(t)]),
        ("train_log_profile", [*tr, "-o", S(d / "m.st"), "--profile", S(pj), "--log", S(pj)]),
        ("train_o_init", [*tr, "-o", S(w), "--init", S(w)]),
        ("train_ckpt_in_data", [*tr, "-o", S(d / "m.st"), "--data", S(raws), "--checkpoint", S(raws / "m.ckpt")]),
        ("train_o_log", [*tr, "-o", S(d / "m.st"), "--log", S(d / "m.st")]),
        ("enhance_o_input", [*en, S(c), "-o", S(c)]),
        ("enhance_o_in_folder", [*en, S(raws), "-o", S(raws / "clean")]),
        ("enhance_o_holds_folder", [*en, S(raws), "-o", S(d)]),
        ("enhance_png_input", [*en, S(c), "-o", S(d / "e.dng"), "--png", S(c)]),
        ("enhance_png_o", [*en, S(c), "-o", S(d / "e.dng"), "--png", S(d / "e.dng")]),
        ("search_plot_model", [pgrf, "search", "--model", S(w), "--procedural", "2", "--plot", S(w)]),
        ("search_plot_in_val", [pgrf, "search", "--model", S(w), "--val", S(raws), "--plot", S(raws / "p.png")]),
        ("eval_csv_root", [*ev, "--csv", S(c)]),
        ("eval_markdown_root", [*ev, "--markdown", S(c)]),
        ("eval_worst_root", [*ev, "--worst", S(c)]),
        ("eval_csv_model", [*ev, "--model", S(w), "--csv", S(w)]),
        ("eval_dump_root", [pgrf, "eval", "--protocol", "synthetic", "--root", S(raws), "--dump", S(raws)]),
        ("eval_dump_holds_root", [pgrf, "eval", "--protocol", "synthetic", "--root", S(raws), "--dump", S(d)]),
        ("eval_csv_markdown", [*ev, "--csv", S(d / "r.csv"), "--markdown", S(d / "r.csv")]),
        ("eval_worst_default", [*ev, "--csv", S(d / "r.csv"), "--markdown", S(d / "r_worst.png")]),
        ("import_o_input", [pgrf, "import-weights", S(w), "-o", S(w)]),
        ("export_o_model", [pgrf, "export-weights", S(w), "-o", S(w)]),
        ("demo_o_holds_photo", [pgrf, "demo", "--photo", S(c), "-o", S(d)]),
        ("demo_o_is_spc", [pgrf, "demo", "--spc", S(w), "-o", S(w)]),
    ]
    return d, cases


def tree(d):
    """Every file under `d` with its bytes."""
    return {str(p.relative_to(d)): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


def run_37_classes(a, pgrf, work, shared, rng, table, failures, peak_box):
    """Issue 37's classes: every case's verdict against what it must be."""
    out = work / "out"

    def fresh():
        if out.exists():
            shutil.rmtree(out)
        out.mkdir()

    def record(cls, cmd, case, v, expect, err):
        got = v if v in ("ok", "refused") else v
        bad = got != expect
        table[f"{cls}/{cmd}"]["ok" if got == "ok" else ("refused" if got == "refused" else "other")] += 1
        if bad:
            label = "accepted" if got == "ok" else got
            failures.append((f"{cls}/{cmd}", case, f"{label} (expected {expect})", err.strip()[:300]))

    def go(args):
        code, err, rss, _ = run(args)
        peak_box[0] = max(peak_box[0], rss)
        return verdict(code, err), err

    if "dngfield" in a.classes:
        for name, data, expect in dngfield_cases(work, pgrf, shared, rng, a.per_class):
            f = work / f"f_{name}.dng"
            f.write_bytes(data)
            for cmd, args in through_readers(pgrf, f, out).items():
                fresh()
                v, err = go(args)
                record("dngfield", cmd, name, v, expect, err)
            f.unlink()
    if "saturate" in a.classes:
        for name, data, expect, extra in saturate_cases(work, pgrf, rng):
            f = work / f"s_{name}.fits"
            f.write_bytes(data)
            for cmd, args in through_readers(pgrf, f, out, extra).items():
                fresh()
                v, err = go(args)
                record("saturate", cmd, name, v, expect, err)
            f.unlink()
    if "counts" in a.classes:
        for name, args, expect in counts_cases(work, pgrf):
            fresh()
            v, err = go(args)
            # clap's own refusals (exit 2) are refusals too.
            if v.startswith("exit 2,"):
                v = "refused"
            record("counts", args[1], name, v, expect, err)
    if "fitssize" in a.classes:
        for name, f, expect in fitssize_cases(work):
            for cmd, args in through_readers(pgrf, f, out).items():
                if cmd == "enhance" and name == "100mp_bayer16":
                    # A real job of minutes (100 MP through the network on
                    # 2 cores), past the run time-out; its memory check is
                    # the Rust test memory_bounds.rs's.
                    continue
                fresh()
                v, err = go(args)
                if expect is None and v in ("ok", "refused"):
                    record("fitssize", cmd, name, v, v, err)
                else:
                    record("fitssize", cmd, name, v, expect or "ok or refused", err)
            f.unlink()
    if "collide" in a.classes:
        d, cases = collide_cases(work, pgrf)
        before = tree(d)
        for name, args in cases:
            v, err = go(args)
            if v.startswith("exit 2,"):
                v = "refused"
            after = tree(d)
            if after != before:
                v = "overwritten" if any(after.get(k) != b for k, b in before.items()) else "wrote"
                for k in set(after) - set(before):
                    (d / k).unlink()
            record("collide", args[1], name, v, "refused", err)
    if "resume" in a.classes:
        fresh()

        def rec(case, v, err):
            record("resume", case.split()[0], case, v,
                   "refused" if case == "resume past --steps" or case.startswith("export") else "ok", err)

        resume_class(work, pgrf, max(1, a.per_class // 4), rec)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    root = Path(__file__).resolve().parent.parent
    ap.add_argument("--pgrf", default=str(root / "target/release/pgrf"))
    ap.add_argument("--shared", default=str(root.parent / "shared/data/raw"))
    ap.add_argument("--per-class", type=int, default=12)
    ap.add_argument("--seed", type=int, default=17)
    ap.add_argument("--work", default=None)
    ap.add_argument("--keep-failures", default=None)
    ap.add_argument("--classes", default="mutate,dngfield,saturate,counts,fitssize,collide,resume",
                    help="comma-separated: mutate (issue 17's five), dngfield, saturate, counts, fitssize, "
                         "collide, resume")
    a = ap.parse_args()
    a.classes = set(a.classes.split(","))
    pgrf = a.pgrf
    work = Path(a.work or tempfile.mkdtemp(prefix="pgrf-campaign-"))
    work.mkdir(parents=True, exist_ok=True)
    shared = Path(a.shared)

    inputs = {}
    chart = work / "chart.dng"
    subprocess.run([pgrf, "chart", "-o", str(chart), "--width", "256", "--height", "192"], check=True)
    inputs["chart"] = chart.read_bytes()
    for name in ["canon550d_colorchart.dng", "canon6d_linear_lossy.dng", "kodak_dc50.kdc"]:
        if (shared / name).exists():
            inputs[name] = (shared / name).read_bytes()
    crop = shared / "dslr_crop_768x512_rggb14.raw"
    if crop.exists():
        dng = work / "dslr_crop.dng"
        subprocess.run(
            [pgrf, "convert", str(crop), "--width", "768", "--height", "512", "--bits", "14",
             "--cfa", "RGGB", "--black", "600", "--white", "15520", "-o", str(dng), "--uncompressed"],
            check=True,
        )
        inputs["dslr_crop.dng"] = dng.read_bytes()
    print(f"campaign: {len(inputs)} inputs, {a.per_class} files per class and input, seed {a.seed}")

    rng = random.Random(a.seed)
    classes = ["truncate", "flip", "zero", "field", "append"] if "mutate" in a.classes else []
    table = defaultdict(lambda: defaultdict(int))
    failures = []
    peak = 0.0
    n_files = 0
    start = time.time()
    for name, data in inputs.items():
        for kind in classes:
            for i in range(a.per_class):
                bad = mutate(kind, data, rng)
                ext = Path(name).suffix or ".dng"
                f = work / f"m_{Path(name).stem}_{kind}_{i}{ext}"
                f.write_bytes(bad)
                n_files += 1
                out = work / "out"
                if out.exists():
                    shutil.rmtree(out)
                out.mkdir()
                cmds = {
                    "info": [pgrf, "info", str(f)],
                    "preview": [pgrf, "preview", str(f), "--half", "-o", str(out / "p.png")],
                    "convert": [pgrf, "convert", str(f), "-o", str(out / "c.dng")],
                }
                if len(bad) < 2 << 20:
                    cmds["enhance"] = [pgrf, "enhance", str(f), "--model", "builtin:spc",
                                       "--ratio", "20", "--noise", "K=1,read=4", "--tile", "256",
                                       "-o", str(out / "e.dng")]
                for cmd, args in cmds.items():
                    code, err, rss, _ = run(args)
                    peak = max(peak, rss)
                    v = verdict(code, err)
                    table[cmd][v] += 1
                    table[f"{cmd}/{kind}"][v] += 1
                    if v not in ("ok", "refused"):
                        failures.append((cmd, f.name, v, err.strip()[:300]))
                        if a.keep_failures:
                            Path(a.keep_failures).mkdir(parents=True, exist_ok=True)
                            shutil.copy(f, Path(a.keep_failures) / f.name)
                if not a.keep_failures or f.name not in {x[1] for x in failures}:
                    f.unlink()
    peak_box = [peak]
    run_37_classes(a, pgrf, work, shared, rng, table, failures, peak_box)
    peak = peak_box[0]
    print(f"{n_files} mutated files, {time.time() - start:.0f} s, peak RSS of any run {peak:.0f} MiB")
    print(f"{'command/class':<20} " + " ".join(f"{k:>9}" for k in ["ok", "refused", "other"]))
    for key in sorted(table):
        row = table[key]
        other = sum(v for k, v in row.items() if k not in ("ok", "refused"))
        print(f"{key:<20} {row['ok']:>9} {row['refused']:>9} {other:>9}")
    for f in failures:
        print("FAIL", *f)
    if not a.work:
        shutil.rmtree(work, ignore_errors=True)
    print(f"{len(failures)} failed")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
