#!/usr/bin/env bash
# Rehearse bench/gpu.sh on this machine's CPU before a lent GPU's minutes are
# spent on it: every pgrf and pgrf-bench command of the script runs with
# `--device cpu` instead of `--device cuda` (the training step at batch 1 x 64
# x 64 and one iteration, the network-only 24 MP bench at 200 x 300), the
# CUDA test executable and nvidia-smi are stubs, and PyTorch runs only if it
# is installed. A command whose arguments went stale (a moved recipe, a flag
# renamed, a model the bench cannot run) fails here with rc != 0 in
# OUT/results.txt, as it would on the card. The phases' numbers are the CPU's
# and mean nothing for the GPU.
#
# Usage: bench/gpu_rehearse.sh OUT   (after cargo build --release -p pgrf-cli -p pgrf-bench)
# Env:   DEADLINE (default 180: the training phase gets about two minutes,
#        past its first validation at step 500 on two cores),
#        ROUNDS (default 1).
set -euo pipefail
out=$1
root=$(cd "$(dirname "$0")/.." && pwd)
rel=$root/target/release
for b in pgrf pgrf-bench; do
  [ -x "$rel/$b" ] || { echo "gpu_rehearse: $rel/$b missing: cargo build --release -p pgrf-cli -p pgrf-bench" >&2; exit 1; }
done
[ -e "$out/results.txt" ] && { echo "gpu_rehearse: $out/results.txt exists (gpu.sh appends): give a new OUT" >&2; exit 1; }
fake=$(mktemp -d)
trap 'rm -rf "$fake"' EXIT
mkdir -p "$fake/bin" "$fake/path"
cat >"$fake/bin/pgrf" <<EOF
#!/usr/bin/env bash
args=(); for a in "\$@"; do [ "\$a" = cuda ] && a=cpu; args+=("\$a"); done
exec "$rel/pgrf" "\${args[@]}"
EOF
cat >"$fake/bin/pgrf-bench" <<EOF
#!/usr/bin/env bash
args=(); prev=
for a in "\$@"; do
  case "\$prev:\$a" in
    *:cuda) a=cpu ;; --size:*) a=64 ;; --batch:*) a=1 ;; --iters:*) a=1 ;;
    --warmup:*) a=0 ;; --frame:*) a=200x300 ;;
  esac
  args+=("\$a"); prev=\$a
done
exec "$rel/pgrf-bench" "\${args[@]}"
EOF
printf '#!/usr/bin/env bash\necho "cuda-test (rehearsal stub): $*"\n' >"$fake/bin/cuda-test"
printf '#!/usr/bin/env bash\necho 0\n' >"$fake/path/nvidia-smi"
chmod +x "$fake/bin/"* "$fake/path/nvidia-smi"
PATH=$fake/path:$PATH DEADLINE=${DEADLINE:-180} ROUNDS=${ROUNDS:-1} \
  "$root/bench/gpu.sh" "$fake/bin" "$out" >/dev/null 2>&1 || true
# The PyTorch lines fail where torch is absent; everything else must pass.
# The training phase ends at its time limit (rc 124 or 130: SIGINT).
bad=$(grep -P '\trc [1-9]' "$out/results.txt" | grep -v '^torch-step' | grep -Pv '^train-spc-cuda\trc (124|130)\t' || true)
cat "$out/results.txt"
if [ -n "$bad" ]; then
  echo "gpu_rehearse: failed:" >&2
  echo "$bad" >&2
  exit 1
fi
echo "gpu_rehearse: every command of bench/gpu.sh ran (see $out/gpu.log)"
