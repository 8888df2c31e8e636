#!/usr/bin/env bash
# Runs every fuzz target of fuzz/ for a short time (EVGATE_FUZZ_SECONDS, default 20) from its
# committed seeds (fuzz/seeds/<target>/), as the README's test command does; a crash fails it
# and leaves the input under fuzz/artifacts/<target>/. Installs cargo-fuzz when missing.
# A longer campaign: EVGATE_FUZZ_SECONDS=1800 bash scripts/fuzz-smoke.sh [TARGET...]
set -euo pipefail
cd "$(dirname "$0")/.."

seconds="${EVGATE_FUZZ_SECONDS:-20}"
if ! cargo fuzz --version >/dev/null 2>&1; then
  echo "fuzz: installing cargo-fuzz (crates.io)"
  cargo install cargo-fuzz --locked --version 0.13.2
fi
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  mapfile -t targets < <(sed -n 's/^name = "\(.*\)"$/\1/p' fuzz/Cargo.toml | grep -v '^evgate-io-fuzz$')
fi
# cargo-fuzz passes nightly-only flags (-Zsanitizer); RUSTC_BOOTSTRAP lets stable accept them.
export RUSTC_BOOTSTRAP=1
cargo fuzz build -O
for target in "${targets[@]}"; do
  # The seeds stay as committed: new inputs go to a scratch corpus.
  corpus="$(mktemp -d)"
  cp fuzz/seeds/"$target"/* "$corpus"/
  log="$(mktemp)"
  echo "== fuzz $target (${seconds}s)"
  # max_len: a nested header or a zip of several members needs far more than the default 4 KB.
  set +e
  cargo fuzz run -O "$target" "$corpus" -- \
    -max_total_time="$seconds" -max_len=1048576 -rss_limit_mb=2048 -timeout=10 \
    -print_final_stats=1 >"$log" 2>&1
  status=$?
  set -e
  grep -E '(DONE|stat::number_of_executed_units|stat::peak_rss_mb|ERROR|SUMMARY|panicked)' "$log" || tail -20 "$log"
  rm -rf "$corpus" "$log"
  if [ "$status" -ne 0 ]; then
    echo "fuzz: $target failed (exit $status); the input is under fuzz/artifacts/$target/" >&2
    exit "$status"
  fi
done
