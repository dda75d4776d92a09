#!/usr/bin/env bash
# Build the fuzz targets and run each for SECONDS (fuzz/README.md).
#
#   fuzz/run.sh SECONDS [TARGET...]     # default: all four targets
#
# Works from a fresh checkout on stable Rust: cargo-fuzz needs unstable
# flags, which RUSTC_BOOTSTRAP=1 unlocks. Seeds come from
# tools/fuzz_corpus.sh when a target's corpus folder is missing or empty.
# Each target runs as one libFuzzer job; its log goes to fuzz/logs/TARGET.log
# and what it finds to fuzz/artifacts/TARGET/. Environment:
#   SANITIZER   address (default) or none
#   FUZZ_ARGS   extra libFuzzer flags, appended (e.g. -seed=1, or
#               "-fork=1 -ignore_ooms=1 -ignore_timeouts=1 -ignore_crashes=1"
#               to keep going after a finding and collect them all)
set -euo pipefail

if [ $# -lt 1 ] || ! [[ $1 =~ ^[0-9]+$ ]]; then
    echo "usage: fuzz/run.sh SECONDS [raw_decode|weights|calibration|profile_json ...]" >&2
    exit 2
fi
seconds=$1
shift
all=(raw_decode weights calibration profile_json)
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=("${all[@]}")

fuzz_dir=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$fuzz_dir/.." && pwd)
cd "$root"
export RUSTC_BOOTSTRAP=1
sanitizer=${SANITIZER:-address}

# Longest input per target: RAW large enough for the small seed files
# (768 x 512 uncompressed DNG, 787 KB); weight and calibration files of
# tiny models and sensors; profiles are a few KB of JSON.
max_len() {
    case $1 in
        raw_decode) echo 1048576 ;;
        weights | calibration) echo 262144 ;;
        profile_json) echo 65536 ;;
        *) echo "unknown target $1" >&2; return 1 ;;
    esac
}
for t in "${targets[@]}"; do max_len "$t" > /dev/null; done

# Release build without debug assertions (-O); see README.md.
build=(-O -s "$sanitizer")
cargo fuzz build "${build[@]}"

for t in "${targets[@]}"; do
    if [ -z "$(ls -A "fuzz/corpus/$t" 2> /dev/null)" ]; then
        tools/fuzz_corpus.sh
        break
    fi
done

mkdir -p fuzz/logs
count() { find "fuzz/artifacts/$1" -maxdepth 1 -type f -name "$2-*" 2> /dev/null | wc -l | tr -d ' '; }
summary=()
for t in "${targets[@]}"; do
    mkdir -p "fuzz/artifacts/$t"
    before=$(find "fuzz/artifacts/$t" -maxdepth 1 -type f | wc -l)
    log=fuzz/logs/$t.log
    echo "fuzz: $t for ${seconds}s (log: $log)" >&2
    set +e
    # shellcheck disable=SC2086
    cargo fuzz run "${build[@]}" "$t" -- \
        -max_total_time="$seconds" -rss_limit_mb=2048 -malloc_limit_mb=2048 -timeout=20 \
        -max_len="$(max_len "$t")" -print_final_stats=1 ${FUZZ_ARGS:-} > "$log" 2>&1
    rc=$?
    set -e
    after=$(find "fuzz/artifacts/$t" -maxdepth 1 -type f | wc -l)
    # libFuzzer's last status line: "#N <event> cov: C ft: F corp: U/S ... exec/s: E ...".
    status=$(grep -E '^#[0-9]+' "$log" | tail -n 1 || true)
    field() { sed -nE "s|.* $1: ([^ ]+).*|\1|p" <<< "$status"; }
    stat() { sed -nE "s/^stat::$1: *([0-9]+).*/\1/p" "$log" | tail -n 1; }
    # With -fork (FUZZ_ARGS) the parent prints no final stats: take the
    # executions and rate from its last status line instead.
    execs=$(stat number_of_executed_units)
    [ -n "$execs" ] || execs=$(sed -nE 's/^#([0-9]+).*/\1/p' <<< "$status")
    rate=$(stat average_exec_per_sec)
    [ -n "$rate" ] || rate=$(field exec/s)
    rss=$(stat peak_rss_mb)
    summary+=("$(printf '%-13s execs %s  exec/s %s  cov %s  ft %s  corpus %s  peak_rss_mb %s  new findings %s (crash %s, timeout %s, oom %s, leak %s in fuzz/artifacts/%s)  exit %s' \
        "$t" "${execs:-?}" "${rate:-?}" "$(field cov)" "$(field ft)" "$(field corp)" "${rss:-?}" \
        "$((after - before))" "$(count "$t" crash)" "$(count "$t" timeout)" "$(count "$t" oom)" \
        "$(count "$t" leak)" "$t" "$rc")")
done

echo
echo "fuzz summary (${seconds}s per target, sanitizer $sanitizer):"
printf '%s\n' "${summary[@]}"
