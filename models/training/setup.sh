#!/usr/bin/env bash
# Creates models/training/.venv from PyPI with the pinned requirements. Idempotent: an existing
# venv whose recorded requirements hash matches is left alone. PYTHON picks the interpreter.
set -euo pipefail
cd "$(dirname "$0")"
python="${PYTHON:-python3}"
stamp=.venv/requirements.sha256
wanted=$(sha256sum requirements.txt | cut -d' ' -f1)
if [ -x .venv/bin/python ] && [ "$(cat "$stamp" 2>/dev/null)" = "$wanted" ]; then
  echo "models/training/.venv: requirements already installed"
  exit 0
fi
[ -x .venv/bin/python ] || "$python" -m venv .venv
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -r requirements.txt
echo "$wanted" > "$stamp"
echo "models/training/.venv: installed requirements.txt"
