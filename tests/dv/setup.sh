#!/usr/bin/env bash
# The end-to-end tests' peer for AEDAT 4 over the network: a virtual environment with
# iniVation's dv-processing from PyPI. Prints the environment's python.
# Usage: tests/dv/setup.sh [VENV_DIR]   (default: target/dv-venv)
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
venv="${1:-$root/target/dv-venv}"
python="${PYTHON:-python3}"
if [ ! -x "$venv/bin/python" ]; then
    "$python" -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$root/tests/dv/requirements.txt" >&2
echo "$venv/bin/python"
