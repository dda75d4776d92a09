#!/usr/bin/env bash
# Per-pixel statistics of 64 bias frames of 12 MP from DNG: pgrf vs numpy
# (rawpy decode + np.stack + mean/var), wall time and peak memory, one run.
# Usage: bench/calib.sh [FRAMES]   (needs ~1.5 GB of free disk in $TMPDIR)
set -euo pipefail
cd "$(dirname "$0")/.."
frames="${1:-64}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
cargo build --release --locked -p pgrf-cli -p pgrf-bench >/dev/null
python3 -c "import rawpy, numpy" 2>/dev/null || python3 -m pip install --quiet rawpy numpy
echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), $(free -g | awk '/Mem:/{print $2}') GiB"
target/release/pgrf simulate-sensor --preset a7s2-iso1600 --frames "$frames" --width 4256 --height 2848 --stacks bias -o "$work/vs" 2>/dev/null
sync
p=$(target/release/pgrf-bench stack "$work/vs/bias" --json)
n=$(python3 bench/calib_numpy.py "$work/vs/bias")
python3 - "$p" "$n" <<'PY'
import json, sys
p, n = json.loads(sys.argv[1]), json.loads(sys.argv[2])
print(f"pgrf : {p['total_s']:7.2f} s, peak {p['peak_rss_mib']:7.0f} MiB, decode alone {p['decode_only_s']:.2f} s ({100*p['decode_fraction']:.0f}% of the run), {p['threads']} threads")
print(f"numpy: {n['total_s']:7.2f} s, peak {n['peak_rss_mib']:7.0f} MiB (decode {n['decode_s']:.2f} s)")
print(f"numpy/pgrf time {n['total_s']/p['total_s']:.2f}x, memory {n['peak_rss_mib']/p['peak_rss_mib']:.1f}x")
PY
