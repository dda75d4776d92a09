#!/usr/bin/env bash
# Issue 36's measure (MODELS.md, "Noise-aware models", "The measure"): the three real mosaics
# of ../shared/data/raw plus two photos the training held out, made dark with the Sony A7S2's
# noise at ISO 400/1600/6400/12800 and the Canon EOS 5D Mark IV's (never trained) at ISO
# 200/800/3200, ratios 20/100/200, uncalibrated (each capture keeps its dark-level offset),
# centre 256 x 256 packed crops; every capture also restored by VST + BM3D given the true
# parameters (bench/vst_bm3d.py, PyPI bm3d 4.0.3) and scored for the noisy input.
#
# With DARKTABLE_PROFILES=darktable's noiseprofiles.json (its data/ file; installed as
# /usr/share/darktable/noiseprofiles.json), also two darktable Poisson-Gaussian profiles: the
# Canon PowerShot G1 X at ISO 100 (a low gain, K 0.6 DN/e-) and 6400 (a high gain, K 41 DN/e-),
# cameras none of the models learnt. With BLIND=1 every run is repeated with the noise-aware
# models told the blind estimate of each capture's noise (`--blind-noise`) instead of the truth:
# what `pgrf enhance` does with a camera it has no profile of (OUT/NAME-blind.csv; the CSVs hold
# the told and the true K and read noise).
#
# With NO_BM3D=1 the BM3D column is left out (its outputs depend only on the seeded captures, so
# a table measured once stands for new models: MODELS.md's), and the run costs only the models'.
#
# Usage: bench/noise_aware_measure.sh OUT MODEL...   (MODEL: builtin:spc, a weight file, ...)
#   PHOTOS (default ~/.cache/pgrf/photos, tools/fetch_photos.sh's folder) must hold the
#   held-out photos plasma-workspace-wallpapers__Kite.jpg and __Path.jpg.
# Writes OUT/{a7s2,5d4,dt-low,dt-high}.csv and .md; the captures (OUT/dump-*) and BM3D's outputs
# (OUT/bm3d-*) are kept and reused, so a stopped run continues and new models cost only their
# own time. JOBS=N runs N BM3D cases at once.
set -euo pipefail
cd "$(dirname "$0")/.."
out="$1"; shift
photos="${PHOTOS:-$HOME/.cache/pgrf/photos}"
data=../shared/data/raw
cargo build --release --locked -p pgrf-cli >/dev/null
pgrf=target/release/pgrf
[ -n "${NO_BM3D:-}" ] || python3 -c "import bm3d" 2>/dev/null || python3 -m pip install --quiet bm3d==4.0.3 numpy
mkdir -p "$out/realset"
cp -n "$data/canon550d_colorchart.dng" "$data/kodak_dc50.kdc" "$out/realset/"
[ -e "$out/realset/dslr_crop.dng" ] || "$pgrf" convert "$data/dslr_crop_768x512_rggb14.raw" \
    --width 768 --height 512 --bits 14 --cfa RGGB --black 600 --white 15520 \
    -o "$out/realset/dslr_crop.dng" >/dev/null
cp -n "$photos/plasma-workspace-wallpapers__Kite.jpg" "$photos/plasma-workspace-wallpapers__Path.jpg" "$out/realset/"
models=()
for m in "$@"; do models+=(--model "$m"); done
dt=()
[ -n "${DARKTABLE_PROFILES:-}" ] && dt=(--darktable-profiles "$DARKTABLE_PROFILES")
run() { # NAME PROFILE ISOS
    local name=$1 profile=$2 isos=$3
    local common=(eval --protocol synthetic --root "$out/realset" --profile "$profile" --iso "$isos"
        --ratio 20,100,200 --uncalibrated --crop 256 --quiet "${dt[@]}")
    if [ ! -d "$out/dump-$name" ]; then
        mkdir -p "$out/dump-$name.part"
        "$pgrf" "${common[@]}" --dump "$out/dump-$name.part" >/dev/null
        mv "$out/dump-$name.part" "$out/dump-$name"
    fi
    local bm3d=()
    if [ -z "${NO_BM3D:-}" ]; then
        python3 bench/vst_bm3d.py "$out/dump-$name" "$out/bm3d-$name" --resume --jobs "${JOBS:-1}"
        bm3d=(--outputs "vst-bm3d=$out/bm3d-$name")
    fi
    "$pgrf" "${common[@]}" "${models[@]}" "${bm3d[@]}" \
        --csv "$out/$name.csv" --markdown "$out/$name.md"
    if [ -n "${BLIND:-}" ]; then
        "$pgrf" "${common[@]}" "${models[@]}" "${bm3d[@]}" --blind-noise \
            --csv "$out/$name-blind.csv" --markdown "$out/$name-blind.md"
    fi
}
run a7s2 sony-a7s2 400,1600,6400,12800
run 5d4 canon-eos5d4 200,800,3200
if [ -n "${DARKTABLE_PROFILES:-}" ]; then
    run dt-low "darktable:Canon PowerShot G1 X" 100
    run dt-high "darktable:Canon PowerShot G1 X" 6400
else
    echo "DARKTABLE_PROFILES not set: the darktable profiles' rows are skipped" >&2
fi
