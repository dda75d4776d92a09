#!/usr/bin/env bash
# Full PGRF noise model on a 12.1 MP A7S2-sized frame: pgrf vs the same model
# in numpy (bench/pgrf_noise_numpy.py), measured in one run, plus this
# machine's memory-bandwidth floor.  Usage: bench/synth.sh [FRAMES]
set -euo pipefail
cd "$(dirname "$0")/.."
frames="${1:-10}"
cargo build --release --locked -p pgrf-bench >/dev/null
python3 -c "import numpy" 2>/dev/null || python3 -m pip install --quiet numpy
echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)"
p=$(target/release/pgrf-bench synth --frames "$frames" --json)
n=$(python3 bench/pgrf_noise_numpy.py --frames "$frames")
python3 - "$p" "$n" <<'PY'
import json, sys
p, n = json.loads(sys.argv[1]), json.loads(sys.argv[2])
print(f"pgrf : {p['ms_median']:8.1f} ms/frame ({p['megapixels_per_s']:.1f} MP/s, {p['threads']} threads)")
print(f"numpy: {n['ms_median']:8.1f} ms/frame ({n['megapixels_per_s']:.1f} MP/s, numpy {n['numpy']})")
print(f"numpy/pgrf: {n['ms_median']/p['ms_median']:.2f}x")
print(f"bandwidth {p['bandwidth_gb_s']:.1f} GB/s, {p['bytes_per_frame']/1e6:.0f} MB/frame -> floor {p['floor_ms']:.1f} ms; pgrf at {p['ratio_to_floor']:.1f}x the floor")
PY
