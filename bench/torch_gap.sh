#!/usr/bin/env bash
# Issue 55: the training step's gap to PyTorch, kernel by kernel, in one run (BENCHMARKS.md, "the gap
# to PyTorch kernel by kernel"): pgrf-bench's --breakdown of the built-in SPC's U-Net (width 16,
# batch 4 x 128 x 128) for the default build and an `--features avx512` build beside
# bench/torch_breakdown.py, three rounds at 1 and 2 threads; then the SR3 default step once each.
#   PGRF_BENCH=target/release/pgrf-bench PGRF_BENCH_AVX512=/path/to/avx512/pgrf-bench \
#   PYTHON=venv/bin/python bench/torch_gap.sh OUT
# Needs an idle machine (nothing else on the cores); writes one file per run into OUT.
set -euo pipefail
out=${1:?usage: bench/torch_gap.sh OUT}
mkdir -p "$out"
cd "$(dirname "$0")/.."
py=${PYTHON:-python3}
builds=("def:${PGRF_BENCH:-target/release/pgrf-bench}")
[ -n "${PGRF_BENCH_AVX512:-}" ] && builds+=("v4:$PGRF_BENCH_AVX512")
{ grep -m1 "model name" /proc/cpuinfo; grep -m1 flags /proc/cpuinfo | tr ' ' '\n' | grep -E "avx|fma" | tr '\n' ' '; echo; } > "$out/cpu.txt"
cat /proc/loadavg > "$out/load_start.txt"
for round in 1 2 3; do
  for t in 1 2; do
    for b in "${builds[@]}"; do
      RAYON_NUM_THREADS=$t "${b#*:}" train --net unet --batch 4 --size 128 --width 16 --iters 6 --warmup 2 --breakdown \
        > "$out/unet_${b%%:*}_t${t}_r$round.txt" 2>&1
    done
    OMP_NUM_THREADS=$t "$py" bench/torch_breakdown.py --net unet --width 16 --batch 4 --size 128 --threads "$t" --steps 6 \
      2>/dev/null > "$out/unet_torch_t${t}_r$round.txt"
  done
done
for t in 1 2; do
  for b in "${builds[@]}"; do
    RAYON_NUM_THREADS=$t "${b#*:}" train --net sr3 --batch 2 --size 128 --iters 3 --warmup 1 --json > "$out/sr3_${b%%:*}_t${t}.txt" 2>&1
  done
  OMP_NUM_THREADS=$t "$py" bench/torch_breakdown.py --net sr3 --batch 2 --size 128 --threads "$t" --steps 2 \
    2>/dev/null > "$out/sr3_torch_t${t}.txt"
done
cat /proc/loadavg > "$out/load_end.txt"
