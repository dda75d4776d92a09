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


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    root = Path(__file__).resolve().parent.parent
    ap.add_argument("--pgrf", default=str(root / "target/release/pgrf"))
    ap.add_argument("--shared", default=str(root.parent / "shared/data/raw"))
    ap.add_argument("--per-class", type=int, default=12)
    ap.add_argument("--seed", type=int, default=17)
    ap.add_argument("--work", default=None)
    ap.add_argument("--keep-failures", default=None)
    a = ap.parse_args()
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
    classes = ["truncate", "flip", "zero", "field", "append"]
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
                                       "--ratio", "20", "--tile", "256", "-o", str(out / "e.dng")]
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
