#!/usr/bin/env bash
# Forward and training-step time of the SID U-Net (w=32) and the SR3 velocity
# field at batch 2 x 4 x 128 x 128 on the CPU: pgrf (burn 0.21, Flex backend)
# with burn's own operations (`--kernels burn`, before issue 15) and with
# pgrf's (`--kernels pgrf`, the default) vs the same architectures in PyTorch
# (bench/train_torch.py), same thread count, measured one after the other in
# this run (burn ops, pgrf ops, then PyTorch, per network).
# Usage: bench/train.sh [ITERS] [THREADS] [SR3_ITERS]
#   ITERS: timed iterations for the U-Net (default 10), after 2 warm-ups
#   THREADS: rayon threads for pgrf, torch.set_num_threads (default: all cores)
#   SR3_ITERS: timed iterations for SR3 (default ITERS; one SR3 step takes
#              tens of seconds on two cores), after 1 warm-up
set -euo pipefail
cd "$(dirname "$0")/.."
iters="${1:-10}"
threads="${2:-$(nproc)}"
sr3_iters="${3:-$iters}"
cargo build --release --locked -q -p pgrf-bench
python3 -c "import torch" 2>/dev/null || python3 -m pip install --quiet torch --index-url https://download.pytorch.org/whl/cpu \
  || python3 -m pip install --quiet torch
echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs); $threads threads; load $(cut -d' ' -f1-3 /proc/loadavg)"
run() { # NET ITERS WARMUP -> "burn_ops_json pgrf_ops_json torch_json"
  local b p t expect
  b=$(RAYON_NUM_THREADS="$threads" target/release/pgrf-bench train --net "$1" --iters "$2" --warmup "$3" --kernels burn --json)
  p=$(RAYON_NUM_THREADS="$threads" target/release/pgrf-bench train --net "$1" --iters "$2" --warmup "$3" --kernels pgrf --json)
  expect=$(python3 -c 'import json,sys; r=json.loads(sys.argv[1]); print(json.dumps({sys.argv[2]: r[sys.argv[2]]["params"]}))' "$p" "$1")
  t=$(python3 bench/train_torch.py --net "$1" --iters "$2" --warmup "$3" --threads "$threads" --expect-params "$expect")
  printf '%s\n%s\n%s\n' "$b" "$p" "$t"
}
unet=$(run unet "$iters" 2)
sr3=$(run sr3 "$sr3_iters" 1)
python3 - "$unet" "$sr3" <<'PY'
import json, sys
rows = []
for block, key, name in ((sys.argv[1], "unet", "SID U-Net w=32"), (sys.argv[2], "sr3", "SR3 (default)")):
    b, p, t = (json.loads(l) for l in block.splitlines())
    assert b["threads"] == p["threads"] == t["threads"], (b["threads"], p["threads"], t["threads"])
    assert (b["kernels"], p["kernels"]) == ("burn", "pgrf")
    rows.append((name, p, t, b[key], p[key], t[key]))
_, p, t, *_ = rows[0]
print(f"pgrf: burn {p['burn']} ({p['backend']}, malloc: {p['malloc']}), {p['threads']} threads; PyTorch {t['torch']}, {t['threads']} threads")
print(f"batch {p['batch']} x 4 x {p['size']} x {p['size']}; medians; 'burn ops' = --kernels burn, 'pgrf ops' = --kernels pgrf")
print(f"{'':26} {'params':>11} {'iters':>5} {'burn ops ms':>11} {'pgrf ops ms':>11} {'torch ms':>9} {'burn/torch':>10} {'pgrf/torch':>10}")
for name, p, t, bo, po, to in rows:
    assert bo["params"] == po["params"] == to["params"], (name, bo["params"], to["params"])
    for what, label in (("forward_ms", "forward"), ("train_step_ms", "train step")):
        print(f"{name + ' ' + label:26} {po['params']:>11} {p['iters']:>5} {bo[what]:11.1f} {po[what]:11.1f} {to[what]:9.1f} {bo[what] / to[what]:9.2f}x {po[what] / to[what]:9.2f}x")
PY
