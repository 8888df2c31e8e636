#!/usr/bin/env bash
# The project's test command (README, CI): installs what the tests need, then runs formatting,
# lints, the Rust tests (unit, property, end-to-end with the real binaries) and the Python tests
# of the training code and the scripts.
set -euo pipefail
cd "$(dirname "$0")/.."

# Disk is what a fresh machine runs short of (torch with its CUDA libraries, the test build):
# say how much there is, so a failure for space reads as such.
df -h . "${TMPDIR:-/tmp}" | sed 's/^/disk: /'
free_kb=$(df -Pk . 2>/dev/null | awk 'NR == 2 { print $4 }' || true)
if [ -n "$free_kb" ] && [ ! -d models/training/.venv ] && [ "$free_kb" -lt $((10 * 1024 * 1024)) ]; then
  echo "disk: warning: $((free_kb / 1024 / 1024)) GB free here; a first run needs about 10 GB" \
    "(the training environment 4.7 GB, the Rust test build 4-5 GB)" >&2
fi
bash scripts/fetch-onnxruntime.sh
bash models/training/setup.sh
bash scripts/setup-hdf5.sh

echo "== cargo fmt --check"
cargo fmt --all --check
echo "== cargo clippy"
cargo clippy --workspace --all-targets --features evgate/dsec -- -D warnings
echo "== fuzz: every target for ${EVGATE_FUZZ_SECONDS:-20} s from its committed seeds"
bash scripts/fuzz-smoke.sh
echo "== cargo build of the binaries the end-to-end tests start"
# The same commands as SERVICE_PACKAGES and EXAMPLES_PACKAGE in tests/lib.rs: the tests' own build then finds them fresh
# and never compiles or runs a build script from inside a test.
cargo build --bins -p evgate -p evgate-gate -p evgate-infer -p evgate-ingest
cargo build --examples -p evgate-examples
echo "== cargo test"
cargo test --workspace --features evgate/dsec
echo "== pytest (models/training, tools)"
models/training/.venv/bin/python -m pytest -q models/training/tests tools/tests
