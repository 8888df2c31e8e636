#!/usr/bin/env bash
# Interleaved Rust-bench runs of several exports, so that all see the same load on a shared
# machine: for each repetition and each (threads, K) setting, every export runs in turn.
# Writes OUT_DIR/rust-bench-<label>-K<k>-<t>threads-rep<r>.json (summarise.py tabulates them).
#   bash evidence/models/latency/run-interleaved.sh OUT_DIR REPETITIONS LABEL=MODEL.onnx[@spin] [LABEL=MODEL.onnx ...]
# FIRST_REPETITION (default 1) numbers a later batch after an earlier one in the same OUT_DIR;
# SETTINGS (default "2:8 2:4 2:1 1:8 1:1") lists threads:K pairs. A MODEL.onnx@spin spec runs that
# export with spinning ONNX Runtime worker threads (EVGATE_BENCH_SPIN=true).
set -euo pipefail
cd "$(dirname "$0")/../../.."
if [ $# -lt 3 ]; then
  sed -n '2,8p' "$0" >&2
  exit 2
fi
out=$1 repetitions=$2
shift 2
for spec in "$@"; do
  model=${spec#*=}
  if [[ "$spec" != *=* || ! -f "${model%@spin}" ]]; then
    echo "run-interleaved: '$spec' is not LABEL=MODEL.onnx[@spin] with an existing file" >&2
    exit 2
  fi
done
bench=$(cargo bench -p evgate-benches --bench inference --no-run --message-format=json 2>/dev/null |
  sed -n 's/.*"executable":"\([^"]*inference-[^"]*\)".*/\1/p' | tail -1)
mkdir -p "$out"
first=${FIRST_REPETITION:-1}
for rep in $(seq "$first" $((first + repetitions - 1))); do
  for setting in ${SETTINGS:-2:8 2:4 2:1 1:8 1:1}; do
    threads=${setting%:*} horizons=${setting#*:}
    for spec in "$@"; do
      label=${spec%%=*} model=${spec#*=} spin=false
      if [[ "$model" == *@spin ]]; then
        model=${model%@spin} spin=true
      fi
      echo "rep $rep: $label K=$horizons threads=$threads spin=$spin" >&2
      EVGATE_BENCH_MODEL=$model EVGATE_BENCH_HORIZONS=$horizons EVGATE_BENCH_THREADS=$threads EVGATE_BENCH_SPIN=$spin \
        EVGATE_BENCH_WINDOWS=100 \
        EVGATE_BENCH_JSON="$out/rust-bench-$label-K$horizons-${threads}threads-rep$rep.json" "$bench" >/dev/null
    done
  done
done
