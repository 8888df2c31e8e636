#!/usr/bin/env bash
# Interleaved Rust-bench runs of two exports of the same weights, so that both see the same
# load on a shared machine: for each repetition, each (threads, K) setting runs the old export
# and then the new one. Writes <dir>/rust-bench-<label>-K<k>-<t>threads-rep<r>.json.
#   bash models/reports/latency/run-interleaved.sh OLD.onnx NEW.onnx OUT_DIR [REPETITIONS]
set -euo pipefail
cd "$(dirname "$0")/../../.."
old=$1 new=$2 out=$3 repetitions=${4:-3}
bench=$(cargo bench -p evgate-benches --bench inference --no-run --message-format=json 2>/dev/null |
  sed -n 's/.*"executable":"\([^"]*inference-[^"]*\)".*/\1/p' | tail -1)
mkdir -p "$out"
for rep in $(seq 1 "$repetitions"); do
  for setting in 2:8 2:4 2:1 1:8 1:1; do
    threads=${setting%:*} horizons=${setting#*:}
    for label in old new; do
      model=$old
      [ "$label" = new ] && model=$new
      echo "rep $rep: $label K=$horizons threads=$threads" >&2
      EVGATE_BENCH_MODEL=$model EVGATE_BENCH_HORIZONS=$horizons EVGATE_BENCH_THREADS=$threads \
        EVGATE_BENCH_WINDOWS=100 \
        EVGATE_BENCH_JSON="$out/rust-bench-$label-K$horizons-${threads}threads-rep$rep.json" "$bench" >/dev/null
    done
  done
done
