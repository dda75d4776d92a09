#!/usr/bin/env bash
# PSNR + SSIM under the ELD protocol on a 4 x 1424 x 2128 packed pair: pgrf
# (all cores, and one thread) vs scikit-image, measured in one run, with the
# scores of both side by side.  Usage: bench/ssim.sh [ITERS] [SKIMAGE_ITERS]
# Needs numpy + scikit-image; set PYTHON to an interpreter that has them
# (default python3; e.g. python3 -m venv /tmp/skvenv && /tmp/skvenv/bin/pip
# install scikit-image numpy && PYTHON=/tmp/skvenv/bin/python bench/ssim.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
iters="${1:-10}"
sk_iters="${2:-3}"
py="${PYTHON:-python3}"
cargo build --release --locked -p pgrf-bench >/dev/null
"$py" -c "import numpy, skimage" 2>/dev/null || "$py" -m pip install --quiet numpy scikit-image
echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)"
p=$(target/release/pgrf-bench ssim --iters "$iters" --json)
p1=$(RAYON_NUM_THREADS=1 target/release/pgrf-bench ssim --iters "$iters" --json)
k=$("$py" bench/ssim_skimage.py --iters "$sk_iters")
"$py" - "$p" "$p1" "$k" <<'PY'
import json, sys
p, p1, k = (json.loads(a) for a in sys.argv[1:4])
print(f"pgrf ({p['threads']} threads): {p['ms_median']:8.1f} ms (min {p['ms_min']:.1f}; without correction {p['ms_median_uncorrected']:.1f})")
print(f"pgrf (1 thread) : {p1['ms_median']:8.1f} ms")
print(f"scikit-image    : {k['metrics_f64_ms_median']:8.1f} ms float64 calls (min {k['metrics_f64_ms_min']:.1f}), "
      f"{k['full_f64_ms_median']:.1f} ms whole protocol, {k['metrics_f32_ms_median']:.1f} ms float32 calls "
      f"(skimage {k['skimage']}, scipy {k['scipy']}, numpy {k['numpy']})")
print(f"ratio skimage float64 calls / pgrf: {k['metrics_f64_ms_median']/p['ms_median']:.1f}x "
      f"(1 thread: {k['metrics_f64_ms_median']/p1['ms_median']:.1f}x); "
      f"whole protocol: {k['full_f64_ms_median']/p['ms_median']:.1f}x; float32 calls: {k['metrics_f32_ms_median']/p['ms_median']:.1f}x")
dp, ds, dg = p['psnr'] - k['psnr'], p['ssim'] - k['ssim'], p['gain'] - k['gain']
print(f"scores: pgrf PSNR {p['psnr']:.9f} SSIM {p['ssim']:.9f} gain {p['gain']:.9f}; "
      f"skimage PSNR {k['psnr']:.9f} SSIM {k['ssim']:.9f}; diff {dp:.1e} dB, {ds:.1e}, gain {dg:.1e}")
print(f"         skimage on float32 (ELD's literal path): PSNR {k['psnr_f32']:.9f} SSIM {k['ssim_f32']:.9f}")
PY
