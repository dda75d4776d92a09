#!/usr/bin/env bash
# pgrf on an NVIDIA GPU in one run (issue 50), in order of value: the CUDA
# tests, the training step against PyTorch on the same card, 24 MP enhance
# end to end, then a stretch of real training on the card.
#
# Usage: bench/gpu.sh BIN OUT
#   BIN  a folder with `pgrf`, `pgrf-bench` and `cuda-test` (the executable of
#        `cargo test --release --features cuda -p pgrf-nn --test cuda --no-run`),
#        all built with `--features cuda`
#   OUT  where the log and the numbers go (created)
# Env: DEADLINE (seconds after which no new phase starts, default 360),
#      ROUNDS (training-step comparisons, pgrf and PyTorch alternating; default 2).
# Needs nvidia-smi and python3 with PyTorch (CUDA); nothing is fetched.
# Rehearse it here first: bench/gpu_rehearse.sh OUT (the CPU in the card's place).
# Peak GPU memory is nvidia-smi's memory.used sampled every 100 ms during
# each command (the whole process: burn's memory pool, PyTorch's caching
# allocator and the CUDA context), written to OUT/results.txt.
set -uo pipefail
bin=$(cd "$1" && pwd)
out=$2
mkdir -p "$out"
cd "$(dirname "$0")/.."
exec > >(tee -a "$out/gpu.log") 2>&1
deadline=${DEADLINE:-360}
rounds=${ROUNDS:-2}
t0=$(date +%s)
elapsed() { echo $(($(date +%s) - t0)); }
results=$out/results.txt
work=$(mktemp -d)

# measure NAME TIMEOUT CMD...: run, time it, record the peak GPU memory.
measure() {
  local name=$1 limit=$2 rc s e peak
  shift 2
  echo "== [$(elapsed) s] $name: $*"
  nvidia-smi --query-gpu=memory.used --format=csv,noheader,nounits -lms 100 >"$work/mem" 2>/dev/null &
  local smi=$!
  s=$(date +%s%N)
  timeout -s INT "$limit" "$@"
  rc=$?
  e=$(date +%s%N)
  kill "$smi" 2>/dev/null
  wait "$smi" 2>/dev/null
  peak=$(sort -n "$work/mem" | tail -1)
  # To stderr (and the results), so that a caller's `| tee -a results` of
  # the command's own output does not record the line twice.
  printf '%s\trc %s\twall %s ms\tpeak GPU %s MiB\n' "$name" "$rc" "$(((e - s) / 1000000))" "${peak:-?}" | tee -a "$results" >&2
  return $rc
}
late() {
  if [ "$(elapsed)" -ge "$deadline" ]; then
    echo "== [$(elapsed) s] past the deadline: skipping $1" | tee -a "$results"
    return 0
  fi
  return 1
}

# burn's CUDA runtime opens libcuda and libnvrtc at run time: put the
# toolkit's libraries on the search path if the loader does not know them.
if ! ldconfig -p | grep -q 'libnvrtc.so'; then
  nvrtc=$(find /usr/local /opt -name 'libnvrtc.so*' 2>/dev/null | head -1)
  [ -n "$nvrtc" ] && export LD_LIBRARY_PATH="$(dirname "$nvrtc")${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
fi
echo "nvrtc: $(ldconfig -p | grep -m1 libnvrtc.so || echo "${nvrtc:-none found}")"
nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv | tee -a "$results"
python3 -c 'import torch; print("torch", torch.__version__, "cudnn", torch.backends.cudnn.version())' | tee -a "$results"
grep -m1 'model name' /proc/cpuinfo | tee -a "$results"

# burn's CUDA backend compiles every kernel at first use (NVRTC) and
# autotunes the matrix and convolution kernels by compiling and timing
# candidates. Keep the compiled PTX and the autotune results on disk (so a
# later process of this run reuses them), tune at the minimal level unless
# CUBECL_AUTOTUNE_LEVEL says otherwise, and log both to OUT.
if [ ! -f cubecl.toml ]; then
  cat >cubecl.toml <<TOML
[compilation]
cache = "target"
[compilation.logger]
level = "basic"
file = "$work/compile.log"
[autotune]
level = "${CUBECL_AUTOTUNE_LEVEL:-minimal}"
[autotune.logger]
level = "full"
file = "$work/autotune.log"
TOML
  trap 'rm -f cubecl.toml' EXIT
fi
( while sleep 20; do
    echo "   .. [$(elapsed) s] kernels compiled: $(grep -c . "$work/compile.log" 2>/dev/null || echo 0) log lines, autotune: $(grep -c . "$work/autotune.log" 2>/dev/null || echo 0) lines, GPU $(nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv,noheader)"
  done ) &
monitor=$!
keep_logs() {
  kill "$monitor" 2>/dev/null
  for f in compile autotune; do
    [ -f "$work/$f.log" ] && tail -c 4000000 "$work/$f.log" >"$out/cubecl-$f.log"
  done
}

# 0. Does burn's CUDA runtime start at all? If not, say why and stop early
#    (the rest would only repeat the failure).
if ! measure smoke "${SMOKE_LIMIT:-150}" "$bin/pgrf-bench" train --device cuda --net unet --width 8 --batch 1 --size 32 --iters 1 --warmup 0; then
  echo "CUDA did not start; libraries found:"
  find / -xdev \( -name 'libcuda.so*' -o -name 'libnvrtc*.so*' \) 2>/dev/null | head -20
  keep_logs
  exit 1
fi

# 1. Correct: CPU and CUDA on the same weights and inputs.
measure cuda-tests 180 "$bin/cuda-test" --ignored --nocapture --test-threads 1

# 2. The training step against PyTorch, batch 8 x 4 x 256 x 256.
step=(--batch 8 --size 256 --iters 10 --warmup 3)
for r in $(seq 1 "$rounds"); do
  for net in unet sr3; do
    late "step $net round $r" && break 2
    measure "pgrf-step-$net-$r" 120 "$bin/pgrf-bench" train --device cuda --net "$net" --width 32 "${step[@]}" --json \
      | tee -a "$results"
    measure "torch-step-$net-$r" 60 python3 bench/train_torch.py --device cuda --net "$net" --width 32 "${step[@]}" \
      | tee -a "$results"
    measure "torch-step-$net-no-tf32-$r" 60 python3 bench/train_torch.py --device cuda --no-tf32 --net "$net" --width 32 "${step[@]}" \
      | tee -a "$results"
  done
done

# 3. 24 MP end to end (decode, noise lookup, network, DNG write).
if ! late 24mp; then
  "$bin/pgrf" chart --width 6000 --height 4000 -o "$work/c24.dng" >/dev/null &&
    "$bin/pgrf" synth "$work/c24.dng" --profile sony-a7s2 --iso 1600 --ratio 100 -o "$work/n24.dng" >/dev/null
  for rep in 1 2; do
    measure "enhance-24mp-spc-cuda-$rep" 60 "$bin/pgrf" enhance "$work/n24.dng" --model builtin:spc --ratio 100 --device cuda -o "$work/e24-$rep.dng"
  done
  measure enhance-24mp-pgrf-cuda 120 "$bin/pgrf" enhance "$work/n24.dng" --model builtin:pgrf --ratio 100 --device cuda -o "$work/p24.dng"
  measure enhance-24mp-spc-cpu16 60 "$bin/pgrf" enhance "$work/n24.dng" --model builtin:spc --ratio 100 --device cpu -o "$work/e24c.dng"
  "$bin/pgrf" metrics "$work/e24-1.dng" "$work/e24c.dng" | tee -a "$results"
  measure bench-24mp-spc-network 60 "$bin/pgrf-bench" enhance --device cuda --model models/spc.safetensors --frame 2000x3000 --iters 3 --warmup 1 --json \
    | tee -a "$results"
fi

# 4. End to end on a small frame: pgrf enhance on the CPU and on CUDA.
if ! late small-enhance; then
  "$bin/pgrf" synth crates/cli/assets/canon550d_colorchart.dng --profile sony-a7s2 --iso 1600 \
    --ratio 100 --seed 5 -o "$work/n.dng" >/dev/null
  measure enhance-small-cpu 60 "$bin/pgrf" enhance "$work/n.dng" --model builtin:spc --ratio 100 --device cpu -o "$work/cpu.dng"
  measure enhance-small-cuda 60 "$bin/pgrf" enhance "$work/n.dng" --model builtin:spc --ratio 100 --device cuda -o "$work/gpu.dng"
  "$bin/pgrf" metrics "$work/gpu.dng" "$work/cpu.dng" | tee -a "$results"
  measure enhance-small-pgrf-cpu 90 "$bin/pgrf" enhance "$work/n.dng" --model builtin:pgrf --ratio 100 --device cpu -o "$work/cpu2.dng"
  measure enhance-small-pgrf-cuda 60 "$bin/pgrf" enhance "$work/n.dng" --model builtin:pgrf --ratio 100 --device cuda -o "$work/gpu2.dng"
  "$bin/pgrf" metrics "$work/gpu2.dng" "$work/cpu2.dng" | tee -a "$results"
fi

# 5. What a GPU minute buys: the built-in SPC trained on on the card with its
#    own recipe (models/spc.toml: values below black kept, crops weighted by
#    their own error) at the fine-tuning rate of the SPC's earlier stages
#    (1e-4), from its shipped weights, on procedural scenes (photos do not
#    travel), until the time is up; Ctrl-C (SIGINT) writes the weights
#    and the checkpoint. The baseline is the shipped file's validation PSNR
#    on the same pairs (`--steps 0`, on the CPU: 30.49 dB on the 2-core VM);
#    the log's rows say what the minutes gained over it.
left=$((deadline + 60 - $(elapsed)))
if [ "$left" -gt 40 ]; then
  spc=(train spc --config models/spc.toml --data procedural --init models/spc.safetensors)
  "$bin/pgrf" "${spc[@]}" --steps 0 --device cpu \
    --output "$work/spc_base.safetensors" --log "$work/spc_base.log.csv" \
    2>&1 | tr '\r' '\n' | grep 'validation PSNR' | tee -a "$results"
  left=$((deadline + 60 - $(elapsed)))
  measure train-spc-cuda "$left" "$bin/pgrf" "${spc[@]}" --lr 1e-4 --device cuda --workers 12 \
    --steps 20000 --val-every 500 --checkpoint-every 500 --checkpoint "$work/spc_gpu.ckpt" \
    --output "$out/spc_gpu.safetensors" --log "$out/spc_gpu.log.csv"
  [ -f "$work/spc_gpu.ckpt" ] && split -b 15M "$work/spc_gpu.ckpt" "$out/spc_gpu.ckpt.part-"
fi
keep_logs
echo "== [$(elapsed) s] done"
