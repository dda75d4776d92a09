#!/usr/bin/env bash
# The Python package's tests, as CI runs them after the Rust tests: a fresh
# venv (target/pyvenv), maturin, numpy and pytest installed by name from
# PyPI, the package installed from this folder with one `pip install`, then
# pytest. The tests that compare the package with the `pgrf` command use
# the one `cargo test` built (target/debug/pgrf) and fail, not skip, if it
# is missing.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
venv="$root/target/pyvenv"
python="${PYTHON:-python3}"
command -v "$python" >/dev/null || { echo "test.sh: $python not found (Python >= 3.9 with venv)" >&2; exit 1; }
rm -rf "$venv"
"$python" -m venv "$venv"
"$venv/bin/python" -m pip install -q --upgrade pip
"$venv/bin/python" -m pip install -q maturin numpy pytest
"$venv/bin/python" -m pip install "$here"
export PGRF_REQUIRE_CLI=1
export PGRF_BIN="${PGRF_BIN:-$root/target/debug/pgrf}"
cd "$here"
"$venv/bin/python" -m pytest -q tests
