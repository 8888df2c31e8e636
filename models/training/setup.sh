#!/usr/bin/env bash
# Creates models/training/.venv from PyPI with the pinned, complete requirements.lock. Idempotent:
# an existing venv whose recorded lock hash matches is left alone. PYTHON picks the interpreter.
#
# Disk is what limits a fresh machine: torch's CUDA libraries are 4.7 GB installed. So the lock is
# installed one package at a time, without pip's cache: the peak is the installed environment plus
# the largest wheel, not plus every wheel twice (download directory and HTTP cache).
# To change a version: edit requirements.txt, `pip install -r requirements.txt` into a scratch venv,
# and write its `pip freeze` (less triton) into requirements.lock.
set -euo pipefail
cd "$(dirname "$0")"
python="${PYTHON:-python3}"
stamp=.venv/requirements.sha256
wanted=$(sha256sum requirements.lock | cut -d' ' -f1)
if [ -x .venv/bin/python ] && [ "$(cat "$stamp" 2>/dev/null)" = "$wanted" ]; then
  echo "models/training/.venv: requirements already installed"
  exit 0
fi
[ -x .venv/bin/python ] || "$python" -m venv .venv
pip=(.venv/bin/python -m pip --disable-pip-version-check)
"${pip[@]}" install --quiet --no-cache-dir --upgrade pip
mapfile -t packages < <(grep -v '^#' requirements.lock | grep -v '^[[:space:]]*$')
for i in "${!packages[@]}"; do
  echo "models/training/.venv: [$((i + 1))/${#packages[@]}] ${packages[$i]}"
  "${pip[@]}" install --quiet --no-cache-dir --no-deps "${packages[$i]}"
done
echo "$wanted" > "$stamp"
echo "models/training/.venv: installed requirements.lock"
