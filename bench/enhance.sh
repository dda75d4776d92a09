#!/usr/bin/env bash
# Whole-frame inference (issue 6): `pgrf-bench enhance` (pgrf_nn::infer::restore_image,
# burn Flex on the CPU) against the same networks, tiling and samplers in PyTorch
# (bench/enhance_torch.py), measured one after the other in this run (pgrf first, then
# PyTorch, per configuration), same thread count, same input frame, same tiles.
#
# Usage: bench/enhance.sh [CONFIG...]     (default: unet sr3-small sr3-crop euler)
#   unet       SID U-Net w=32 (SPC) on the full 12.1 MP frame (packed 4 x 1424 x 2128),
#              the tile `pgrf enhance` would choose here; median of $UNET_ITERS after 1 warm-up
#   sr3-small  reduced SR3 (inner 32, mults 1,2,4,4, attention at level 3) on the full
#              frame, tile 512, two-stage sampler (2 NFE); one timed run
#   unet-24mp  the same on a 24 MP frame (packed 4 x 2000 x 3000, a 6000 x 4000 sensor)
#   sr3-small-24mp  the reduced SR3 on that 24 MP frame, tile 512, two-stage; one timed run
#   sr3-crop   default SR3 (97.8 M parameters) on a 512 x 512 packed crop (one tile),
#              two-stage; the full frame at tile 512 is extrapolated from it
#   sr3-full   default SR3 on the full frame, tile 512 (tens of minutes on 2 cores)
#   euler      reduced SR3 on a 256 x 256 packed crop: two-stage (median of 3 after
#              1 warm-up) next to Euler-50 (one run)
# Env: THREADS (default: all cores; RAYON_NUM_THREADS and torch.set_num_threads),
#      UNET_ITERS (default 3), RESULTS (file to append the raw JSON lines to).
set -euo pipefail
cd "$(dirname "$0")/.."
threads="${THREADS:-$(nproc)}"
unet_iters="${UNET_ITERS:-3}"
configs=("$@")
[ ${#configs[@]} -gt 0 ] || configs=(unet sr3-small sr3-crop euler)
cargo build --release --locked -q -p pgrf-bench
python3 -c "import torch" 2>/dev/null || python3 -m pip install --quiet torch --index-url https://download.pytorch.org/whl/cpu \
  || python3 -m pip install --quiet torch
echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), $(free -g | awk '/Mem:/ {print $2}') GiB; $threads threads; load $(cut -d' ' -f1-3 /proc/loadavg)"
small=(--net sr3 --inner-channels 32 --channel-mults 1,2,4,4 --attn-levels 3)
rows=$(mktemp)
trap 'rm -f "$rows"' EXIT
run() { # LABEL ITERS WARMUP PGRF_ARGS... ; appends "LABEL<TAB>pgrf_json<TAB>torch_json"
  local label="$1" iters="$2" warmup="$3" p t tile params
  shift 3
  echo "== $label: $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >&2
  p=$(RAYON_NUM_THREADS="$threads" target/release/pgrf-bench enhance "$@" --iters "$iters" --warmup "$warmup" --json)
  echo "   pgrf:    $p" >&2
  tile=$(python3 -c 'import json,sys; print(json.loads(sys.argv[1])["tile"])' "$p")
  params=$(python3 -c 'import json,sys; print(json.loads(sys.argv[1])["params"])' "$p")
  t=$(python3 bench/enhance_torch.py "$@" --tile "$tile" --iters "$iters" --warmup "$warmup" \
        --threads "$threads" --expect-params "$params")
  echo "   PyTorch: $t" >&2
  printf '%s\t%s\t%s\n' "$label" "$p" "$t" >>"$rows"
  if [ -n "${RESULTS:-}" ]; then printf '%s\t%s\t%s\n' "$label" "$p" "$t" >>"$RESULTS"; fi
}
for c in "${configs[@]}"; do
  case "$c" in
    unet) run "SID U-Net w=32, full frame" "$unet_iters" 1 --net unet --width 32 ;;
    sr3-small) run "SR3 small, full frame" 1 0 "${small[@]}" --tile 512 ;;
    unet-24mp) run "SID U-Net w=32, 24 MP frame" "$unet_iters" 1 --net unet --width 32 --frame 2000x3000 ;;
    sr3-small-24mp) run "SR3 small, 24 MP frame" 1 0 "${small[@]}" --frame 2000x3000 --tile 512 ;;
    sr3-crop) run "SR3 default, 512x512 crop" 1 0 --net sr3 --frame 512 --tile 512 ;;
    sr3-full) run "SR3 default, full frame" 1 0 --net sr3 --tile 512 ;;
    euler)
      run "SR3 small, 256x256, two-stage" 3 1 "${small[@]}" --frame 256 --tile 256
      run "SR3 small, 256x256, Euler-50" 1 0 "${small[@]}" --frame 256 --tile 256 --sampler euler:50
      ;;
    *) echo "unknown configuration '$c'" >&2; exit 2 ;;
  esac
done
echo "load after: $(cut -d' ' -f1-3 /proc/loadavg)"
python3 - "$rows" <<'PY'
import json, sys
sys.path.insert(0, "bench")
from enhance_torch import plan_for
rows = [l.rstrip("\n").split("\t") for l in open(sys.argv[1]) if l.strip()]
if not rows:
    sys.exit(0)
p0, t0 = json.loads(rows[0][1]), json.loads(rows[0][2])
print(f"pgrf: burn {p0['burn']} ({p0['device']}); PyTorch {t0['torch']}, {t0['threads']} threads")
hdr = f"{'':34} {'frame':>11} {'tiles':>10} {'NFE':>4} {'pgrf s':>8} {'torch s':>8} {'ratio':>6} {'pgrf s/NFE':>10} {'torch s/NFE':>11} {'pgrf MiB':>8} {'torch MiB':>9}"
print(hdr)
extra = []
for label, pj, tj in rows:
    p, t = json.loads(pj), json.loads(tj)
    assert p["params"] == t["params"], (label, p["params"], t["params"])
    assert (p["tiles"], p["tile_hw"], p["nfe"]) == (t["tiles"], t["tile_hw"], t["nfe"]), (label, p, t)
    assert p["threads"] == t["threads"], (p["threads"], t["threads"])
    frame = f"{p['frame'][1]}x{p['frame'][2]}"
    tiles = f"{p['tiles']}x{p['tile_hw'][0]}x{p['tile_hw'][1]}" if p["tiles"] > 1 else f"1x{p['tile_hw'][0]}x{p['tile_hw'][1]}"
    print(f"{label:34} {frame:>11} {tiles:>10} {p['nfe']:>4} {p['seconds']:8.2f} {t['seconds']:8.2f} "
          f"{p['seconds'] / t['seconds']:5.2f}x {p['seconds_per_eval']:10.2f} {t['seconds_per_eval']:11.2f} "
          f"{p['peak_rss_mib']:8.0f} {t['peak_rss_mib']:9.0f}")
    if p["frame"][1:] != [1424, 2128] and p["tiles"] == 1 and p["tile_hw"][0] == p["tile_hw"][1]:
        side = p["tile_hw"][0]
        r, c, _ = plan_for(1424, 2128, side, p["overlap"], 1)
        n = len(r[0]) * len(c[0])
        extra.append(f"{label}: full 1424x2128 frame at tile {side} = {n} tiles x {p['nfe']} NFE, "
                     f"extrapolated (per-tile time x tiles, not measured): pgrf {p['seconds_per_tile_eval'] * n * p['nfe']:.0f} s, "
                     f"PyTorch {t['seconds_per_tile_eval'] * n * t['nfe']:.0f} s")
print("params: " + "; ".join(f"{l}: {json.loads(p)['params']:,}" for l, p, _ in rows))
for e in extra:
    print(e)
PY
