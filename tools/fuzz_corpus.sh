#!/usr/bin/env bash
# Seed corpus for the cargo-fuzz targets (fuzz/README.md), written into
# fuzz/corpus/TARGET/ (not committed). Seeds are added next to whatever the
# fuzzer has already put there; nothing is deleted.
#
#   tools/fuzz_corpus.sh            # all four targets
#
# Uses a release pgrf binary (PGRF, default target/release/pgrf; built
# with `cargo build --release -p pgrf-cli` if missing) to make small valid
# files, and the shared data next to the checkout (SHARED_DATA, default
# ../shared/data) when it is there:
#
#   raw_decode   the shared RAW files (and broken/ ones) up to RAW_MAX
#                bytes; pgrf charts (64 x 48, 65 x 49 GBRG) compressed and
#                uncompressed; the headerless DSLR crop and the Kodak KDC as
#                DNGs; one bias and one dark frame of a virtual sensor
#   weights      a width-1 SPC model and a tiny residual flow model trained
#                for one step (valid files that build), and the records of
#                models/*.safetensors without their tensors (the full files
#                are megabytes, past the target's max_len; needs python3)
#   calibration  a calibration of a 16 x 16 virtual sensor, and its truth maps
#   profile_json crates/noise/profiles/*.json (valid) and
#                SHARED_DATA/profiles/ELD_*.json (ELD's own parameter files)
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
PGRF=${PGRF:-target/release/pgrf}
SHARED_DATA=${SHARED_DATA:-../shared/data}
RAW_MAX=${RAW_MAX:-1048576}
out=fuzz/corpus

if [ ! -x "$PGRF" ]; then
    echo "fuzz_corpus: $PGRF missing; building it (cargo build --release -p pgrf-cli)" >&2
    cargo build --release -p pgrf-cli
fi

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p "$out"/raw_decode "$out"/weights "$out"/calibration "$out"/profile_json

say() { echo "fuzz_corpus: $*" >&2; }
quiet() { "$@" > "$work/last.log" 2>&1 || { cat "$work/last.log" >&2; return 1; }; }
# Copies are made writable (shared data may be read-only) so a rerun can
# overwrite them.
put() { install -m 0644 "$1" "$2"; }
size_of() { wc -c < "$1" | tr -d ' '; }

# --- raw_decode --------------------------------------------------------------
raw=$out/raw_decode
if [ -d "$SHARED_DATA/raw" ]; then
    for f in "$SHARED_DATA"/raw/* "$SHARED_DATA"/raw/broken/*; do
        [ -f "$f" ] || continue
        # Headerless dumps need geometry flags (they are seeded as DNGs below).
        case $f in *.json | *.md | *.raw) continue ;; esac
        if [ "$(size_of "$f")" -le "$RAW_MAX" ]; then
            put "$f" "$raw/shared_$(basename "$f")"
        else
            say "skipping $f ($(size_of "$f") bytes > RAW_MAX $RAW_MAX)"
        fi
    done
    dump=$SHARED_DATA/raw/dslr_crop_768x512_rggb14.raw
    if [ -f "$dump" ]; then
        geom=(--width 768 --height 512 --cfa RGGB --bits 14 --black 600 --white 15520)
        quiet "$PGRF" convert "$dump" "${geom[@]}" -o "$raw/pgrf_dslr_crop.dng"
        quiet "$PGRF" convert "$dump" "${geom[@]}" --uncompressed -o "$raw/pgrf_dslr_crop_unc.dng"
    fi
    kdc=$SHARED_DATA/raw/kodak_dc50.kdc
    [ -f "$kdc" ] && quiet "$PGRF" convert "$kdc" -o "$raw/pgrf_kodak_dc50.dng"
else
    say "no $SHARED_DATA/raw: RAW seeds are pgrf's own DNGs only"
fi
quiet "$PGRF" chart -o "$raw/pgrf_chart_64x48.dng" --width 64 --height 48
quiet "$PGRF" convert "$raw/pgrf_chart_64x48.dng" --uncompressed -o "$raw/pgrf_chart_64x48_unc.dng"
quiet "$PGRF" chart -o "$work/odd.dng" --width 65 --height 49 --cfa GBRG --black 64 --white 4095
put "$work/odd.dng" "$raw/pgrf_chart_65x49_gbrg.dng"
quiet "$PGRF" convert "$work/odd.dng" --uncompressed -o "$raw/pgrf_chart_65x49_gbrg_unc.dng"

# A 16 x 16 virtual sensor: its frames seed raw_decode (EXIF ISO and
# exposure), its stacks make the calibration.
sensor=$work/sensor
quiet "$PGRF" simulate-sensor --width 16 --height 16 --frames 4 -o "$sensor"
put "$(ls "$sensor"/bias/*.dng | head -n 1)" "$raw/pgrf_sensor_bias.dng"
put "$(ls "$sensor"/dark/*.dng | head -n 1)" "$raw/pgrf_sensor_dark.dng"

# --- calibration -------------------------------------------------------------
quiet "$PGRF" calibrate --bias "$sensor/bias" --dark "$sensor/dark" --flat "$sensor/flat" \
    -o "$out/calibration/pgrf_calibration_16x16.safetensors"
put "$sensor/truth.safetensors" "$out/calibration/pgrf_truth_16x16.safetensors"

# --- weights -----------------------------------------------------------------
tiny=(--patch 16 --steps 1 --val-pairs 1 --val-every 0 --quiet)
quiet "$PGRF" train spc --width 1 "${tiny[@]}" -o "$work/spc_w1.safetensors"
put "$work/spc_w1.safetensors" "$out/weights/pgrf_spc_w1.safetensors"
quiet "$PGRF" train flow --inner-channels 2 --channel-mults 1,2 --res-blocks 1 --attn-levels 1 \
    --norm-groups 1 --residual "${tiny[@]}" -o "$work/flow_tiny.safetensors"
# A searched t2 in the record, as `pgrf enhance` finds it in shipped models.
quiet "$PGRF" search -m "$work/flow_tiny.safetensors" --procedural 1 --pairs 1 --patch 16 --step 0.5
put "$work/flow_tiny.safetensors" "$out/weights/pgrf_flow_tiny.safetensors"
if command -v python3 > /dev/null; then
    for m in models/*.safetensors; do
        [ -f "$m" ] || continue
        # The same safetensors header with its metadata (the pgrf record)
        # and no tensors: a valid file whose record describes a real model.
        python3 - "$m" "$out/weights/record_only_$(basename "$m")" << 'EOF'
import json, struct, sys
src, dst = sys.argv[1], sys.argv[2]
with open(src, "rb") as f:
    n = struct.unpack("<Q", f.read(8))[0]
    header = json.loads(f.read(n))
meta = {"__metadata__": header.get("__metadata__", {})}
text = json.dumps(meta, separators=(",", ":")).encode()
text += b" " * (-len(text) % 8)
with open(dst, "wb") as f:
    f.write(struct.pack("<Q", len(text)) + text)
EOF
    done
else
    say "no python3: models/*.safetensors records not added"
fi

# --- profile_json ------------------------------------------------------------
for f in crates/noise/profiles/*.json; do
    put "$f" "$out/profile_json/$(basename "$f")"
done
if [ -d "$SHARED_DATA/profiles" ]; then
    for f in "$SHARED_DATA"/profiles/ELD_*.json; do
        put "$f" "$out/profile_json/shared_$(basename "$f")"
    done
fi

for t in raw_decode weights calibration profile_json; do
    say "$t: $(ls "$out/$t" | wc -l) files, $(du -sk "$out/$t" | cut -f1) KiB"
done
