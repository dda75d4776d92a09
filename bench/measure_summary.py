#!/usr/bin/env python3
"""Summarise bench/noise_aware_measure.sh's CSVs (issue 51's measure): per camera and ratio the
mean PSNR of every method; the captures restored below their noisy input, and more than 0.5 dB
below a reference method (default vst-bm3d, when its column is there); the black-level median
(thousandths of white) per ISO and ratio for the A7S2.

Usage: bench/measure_summary.py OUT [--reference METHOD] [--bm3d-from OTHER_OUT]
  --bm3d-from: take the reference method's rows from another measure's CSVs (the same seeded
  captures: BM3D's outputs depend on nothing else).
"""
import argparse
import csv
import os
from collections import defaultdict

CAMERAS = [("a7s2", "A7S2"), ("5d4", "5D Mark IV (unseen)"), ("dt-low", "darktable G1 X ISO 100"),
           ("dt-high", "darktable G1 X ISO 6400")]


def rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--reference", default="vst-bm3d")
    ap.add_argument("--bm3d-from")
    a = ap.parse_args()
    below_input = defaultdict(int)
    below_ref = defaultdict(int)
    total = 0
    methods = []
    for key, name in CAMERAS:
        p = os.path.join(a.out, key + ".csv")
        if not os.path.exists(p):
            continue
        rs = rows(p)
        if a.bm3d_from and os.path.exists(os.path.join(a.bm3d_from, key + ".csv")):
            rs += [r for r in rows(os.path.join(a.bm3d_from, key + ".csv")) if r["method"] == a.reference]
        by = defaultdict(dict)
        for r in rs:
            by[(r["id"], r["iso"], r["ratio"])][r["method"]] = r
        ms = []
        for r in rs:
            if r["method"] not in ms:
                ms.append(r["method"])
        if not methods:
            methods = ms
            print("| camera | ratio | " + " | ".join(ms) + " |")
            print("|---|---|" + "---:|" * len(ms))
        for ratio in sorted({k[2] for k in by}, key=float):
            cells = []
            for m in methods:
                v = [float(d[m]["psnr"]) for k, d in by.items() if k[2] == ratio and m in d]
                cells.append(f"{sum(v) / len(v):.2f}" if v else "-")
            print(f"| {name} | x{ratio} | " + " | ".join(cells) + " |")
        for k, d in by.items():
            total += 1
            noisy = float(d["noisy input"]["psnr"])
            ref = float(d[a.reference]["psnr"]) if a.reference in d else None
            for m in methods:
                if m in ("noisy input", a.reference) or m not in d:
                    continue
                p_ = float(d[m]["psnr"])
                below_input[m] += p_ < noisy
                if ref is not None:
                    below_ref[m] += p_ < ref - 0.5
        if key == "a7s2":
            bl = defaultdict(dict)
            for k, d in by.items():
                for m in methods:
                    if m in d and d[m]["black_median"]:
                        bl[(k[1], k[2])].setdefault(m, []).append(float(d[m]["black_median"]))
            print("\nA7S2 black median (thousandths of white; median over the images of the median over black regions)")
            print("| ISO x ratio | " + " | ".join(methods) + " |")
            print("|---|" + "---:|" * len(methods))
            for (iso, ratio) in sorted(bl, key=lambda t: (int(t[0]), float(t[1]))):
                cells = []
                for m in methods:
                    v = sorted(bl[(iso, ratio)].get(m, []))
                    cells.append(f"{1000 * v[len(v) // 2]:+.1f}" if v else "-")
                print(f"| ISO {iso} x{ratio} | " + " | ".join(cells) + " |")
            print()
    print(f"\ncaptures: {total}")
    for m in methods:
        if m in ("noisy input", a.reference):
            continue
        print(f"{m}: below its noisy input {below_input[m]}, more than 0.5 dB below {a.reference} {below_ref[m]}")


if __name__ == "__main__":
    main()
