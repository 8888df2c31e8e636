#!/usr/bin/env bash
# Creates the Python environment of the examples: a virtual environment with the iceoryx2
# bindings of the same version as the Rust crate (the shared-memory layout must match), NumPy,
# and this folder's evgate_reader package.
# Usage: examples/python/setup.sh [VENV_DIR]   (default: target/python-examples-venv)
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
venv="${1:-$root/target/python-examples-venv}"
python="${PYTHON:-python3}"
if [ ! -x "$venv/bin/python" ]; then
    "$python" -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$root/examples/python/requirements.txt"
# From a copy, so that the build leaves nothing in the checkout.
build=$(mktemp -d)
trap 'rm -rf "$build"' EXIT
cp -r "$root/examples/python/pyproject.toml" "$root/examples/python/evgate_reader" "$build/"
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps "$build" >&2
echo "$venv/bin/python"
