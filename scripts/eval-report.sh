#!/usr/bin/env bash
# The README's headline report: `evgate eval` on the test split of the simulator's suite with
# the committed models (S, the model under test, then L when present), plus every model in
# models/ablation (ATC variants and sizes for tables VI and VII) when that folder holds any. Writes JSON, Markdown tables and plots into the report
# folder. Environment: EVGATE_SUITE (default data/suite-v4), EVGATE_REPORT (default
# reports/test-v4); further arguments go to `evgate eval` (e.g. --threads 4, --max-seconds 2).
set -euo pipefail
cd "$(dirname "$0")/.."
suite=${EVGATE_SUITE:-data/suite-v4}
report=${EVGATE_REPORT:-reports/test-v4}
if [ ! -d "$suite/test" ]; then
  echo "eval-report: no test split at $suite/test (generate it with \`evgate sim suite\` or set EVGATE_SUITE)" >&2
  exit 1
fi
bash scripts/fetch-onnxruntime.sh
cargo build --release -p evgate
args=(--suite "$suite" --split test --report "$report" --model models/evgate-S.onnx)
if [ -f models/evgate-L.onnx ]; then
  args+=(--model models/evgate-L.onnx)
fi
if compgen -G "models/ablation/*.onnx" > /dev/null; then
  args+=(--ablation-models models/ablation)
fi
echo "evgate eval ${args[*]} $*" >&2
exec target/release/evgate eval "${args[@]}" "$@"
