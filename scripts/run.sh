#!/usr/bin/env bash
# The main job (README): the full three-process pipeline — ingest on the built-in simulated
# camera, infer with the bundled model, gate — with a live status line and a final summary.
# Installs what it needs (the ONNX Runtime library from PyPI), builds in release mode, then
# passes any arguments on to `evgate run` (e.g. --preset fast --duration 10 --json).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/fetch-onnxruntime.sh
cargo build --release -p evgate -p evgate-ingest -p evgate-infer -p evgate-gate
if [ "$#" -eq 0 ]; then
  set -- --duration 5
fi
exec target/release/evgate run "$@"
