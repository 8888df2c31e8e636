#!/usr/bin/env bash
# Creates the Python environment of the examples: a virtual environment with the iceoryx2
# bindings of the same version as the Rust crate (the shared-memory layout must match).
# Usage: examples/python/setup.sh [VENV_DIR]   (default: target/python-examples-venv)
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
venv="${1:-$root/target/python-examples-venv}"
python="${PYTHON:-python3}"
if [ ! -x "$venv/bin/python" ]; then
    "$python" -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$root/examples/python/requirements.txt"
echo "$venv/bin/python"
