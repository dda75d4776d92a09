#!/usr/bin/env bash
# Decode + pack + normalise: pgrf vs LibRaw (rawpy), measured in one run.
# Usage: bench/decode.sh [ITERS]   (needs ../shared/data and pip access for rawpy)
set -euo pipefail
cd "$(dirname "$0")/.."
iters="${1:-20}"
data="../shared/data/raw"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

cargo build --release --locked -p pgrf-cli -p pgrf-bench >/dev/null
pgrf=target/release/pgrf
python3 -c "import rawpy, numpy" 2>/dev/null || python3 -m pip install --quiet rawpy numpy

# 12-megapixel synthetic DNG written by pgrf (the A7S2's 4240x2832 mosaic),
# lossless-compressed as pgrf writes by default.
"$pgrf" chart --width 4240 --height 2832 -o "$work/chart12mp.dng" 2>/dev/null
files=("$data/canon550d_colorchart.dng" "$work/chart12mp.dng")

echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)"
target/release/pgrf-bench decode "${files[@]}" --iters "$iters" --json > "$work/pgrf.jsonl"
python3 bench/rawpy_decode.py "${files[@]}" --iters "$iters" > "$work/rawpy.jsonl"
python3 - "$work/pgrf.jsonl" "$work/rawpy.jsonl" <<'PY'
import json, sys, os
p = [json.loads(l) for l in open(sys.argv[1])]
r = [json.loads(l) for l in open(sys.argv[2])]
print(f"{'file':<28}{'MP':>6}{'pgrf ms':>10}{'rawpy ms':>10}{'rawpy/pgrf':>12}   (medians; pgrf decode/pack, rawpy decode/pack)")
for a, b in zip(p, r):
    name = os.path.basename(a["file"])
    print(f"{name:<28}{a['megapixels']:>6.2f}{a['total_ms_median']:>10.2f}{b['total_ms_median']:>10.2f}{b['total_ms_median']/a['total_ms_median']:>11.2f}x"
          f"   ({a['decode_ms_median']:.2f}/{a['pack_ms_median']:.2f} vs {b['decode_ms_median']:.2f}/{b['pack_ms_median']:.2f})")
print(f"rawpy {r[0]['rawpy']} (LibRaw {r[0]['libraw']})")
PY
