#!/usr/bin/env bash
# pgrf's Python package vs ELD's numpy noise model (see bench/python_synth.py). Needs the pgrf wheel, torch, scipy in $PYTHON (default python3). Usage: PYTHON=venv/bin/python bench/python_synth.sh [--frames N] [--repeat N] [--workers N]
exec "${PYTHON:-python3}" "$(dirname "$0")/python_synth.py" "$@"
