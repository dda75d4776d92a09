#!/usr/bin/env bash
# Quality per CPU-minute of training, by network size (issue 16's size
# choice): train each size for the same wall-clock budget on the same data,
# noise and validation set, and print validation PSNR against seconds.
#
#   bench/size_curve.sh PHOTOS_DIR OUT_DIR [SECONDS] [THREADS] [NETS]
#
# NETS: spc (default), pgrf, or spc,pgrf: SID U-Net widths 8, 16, 32, or
# SR3 inner channels 8, 16, 32 (x [1, 2, 2, 4], attention at level 3,
# GroupNorm groups min(16, channels), 64 x 64 crops, lr 5e-4, as
# models/next/pgrf.toml).
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
    echo "usage: bench/size_curve.sh PHOTOS_DIR OUT_DIR [SECONDS] [THREADS] [NETS]" >&2
    exit 2
fi
photos=$1
out=$2
seconds=${3:-900}
threads=${4:-2}
nets=${5:-spc}
case ",$nets," in
    *,spc,* | *,pgrf,*) ;;
    *)
        echo "size_curve: NETS must be spc, pgrf or spc,pgrf (got '$nets')" >&2
        exit 2
        ;;
esac
root=$(cd "$(dirname "$0")/.." && pwd)
pgrf=${PGRF:-$root/target/release/pgrf}
mkdir -p "$out"

# Shared by every run: data, noise, crops and validation of models/next.
common=(--data "$photos@3,procedural@1" --profile "sony-a7s2@3,nikon-d850@1"
    --noise-model pgrf --iso-range 400,12800 --ratio-min 20 --ratio-max 300
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

if [[ ",$nets," == *,spc,* ]]; then
    for w in 8 16 32; do
        run "spc_w$w" spc --width "$w" --patch 128 --val-patch 256 --lr 3e-4 --seed 16
    done
fi
if [[ ",$nets," == *,pgrf,* ]]; then
    for c in 8 16 32; do
        run "pgrf_c$c" pgrf --inner-channels "$c" --channel-mults 1,2,2,4 --res-blocks 1 \
            --attn-levels 3 --norm-groups "$((c < 16 ? c : 16))" --patch 64 --val-patch 128 --val-t2 0.5 \
            --lr 5e-4 --seed 17
    done
fi

for log in "$out"/*.log.csv; do
    name=$(basename "$log" .log.csv)
    awk -F, -v n="$name" 'NR > 1 && $5 != "" { printf "%s step %s  %.0f s  val %.2f dB\n", n, $1, $6, $5 }
        NR > 1 { last = $4 } END { printf "%s crops/s (last logged) %s\n", n, last }' "$log"
done
