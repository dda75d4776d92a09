#!/usr/bin/env bash
# Quality per CPU-minute of training, by network size (issue 16's size
# choice): train each size for the same wall-clock budget on the same data,
# noise and validation set, and print validation PSNR against seconds.
#
#   bench/size_curve.sh PHOTOS_DIR OUT_DIR [SECONDS] [THREADS]
#
# PHOTOS_DIR is tools/fetch_photos.sh's folder. Each run is
# `pgrf train spc|pgrf` with the settings of models/next/*.toml except the
# size, stopped by SIGINT after SECONDS (default 900; pgrf saves and writes
# its log on Ctrl-C), with RAYON_NUM_THREADS=THREADS (default 2). Run it on
# an otherwise idle machine: the budget is wall-clock time. The learning
# rate stays at its starting value over such a budget (the schedule's first
# drop is at half the nominal --steps), so sizes are compared at equal
# optimisation settings. Prints, per run, validation PSNR at each
# validation step with the seconds it was reached, and the crops/s.
set -euo pipefail
if [ $# -lt 2 ]; then
    echo "usage: bench/size_curve.sh PHOTOS_DIR OUT_DIR [SECONDS] [THREADS]" >&2
    exit 2
fi
photos=$1
out=$2
seconds=${3:-900}
threads=${4:-2}
root=$(cd "$(dirname "$0")/.." && pwd)
pgrf=${PGRF:-$root/target/release/pgrf}
mkdir -p "$out"

# Shared by every run: data, noise, crops and validation of models/next.
common=(--data "$photos@3,procedural@1" --profile "sony-a7s2@3,nikon-d850@1"
    --noise pgrf --iso-range 400,12800 --ratio-min 20 --ratio-max 300
    --batch 4 --workers 1 --clip-grad 1 --schedule eld --steps 200000
    --residual --val-every 200 --val-pairs 16 --log-every 50
    --checkpoint-every 100000)

run() {
    local name=$1
    shift
    echo "size_curve: $name for ${seconds}s" >&2
    set +e
    RAYON_NUM_THREADS=$threads timeout --foreground -s INT --kill-after=120 "$seconds" \
        "$pgrf" train "$@" "${common[@]}" --quiet \
        -o "$out/$name.safetensors" --log "$out/$name.log.csv" > "$out/$name.out" 2>&1
    set -e
}

run spc_w8 spc --width 8 --patch 128 --val-patch 256 --lr 3e-4 --seed 16
run spc_w16 spc --width 16 --patch 128 --val-patch 256 --lr 3e-4 --seed 16
run spc_w32 spc --width 32 --patch 128 --val-patch 256 --lr 3e-4 --seed 16

for log in "$out"/*.log.csv; do
    name=$(basename "$log" .log.csv)
    awk -F, -v n="$name" 'NR > 1 && $5 != "" { printf "%s step %s  %.0f s  val %.2f dB\n", n, $1, $6, $5 }
        NR > 1 { last = $4 } END { printf "%s crops/s (last logged) %s\n", n, last }' "$log"
done
