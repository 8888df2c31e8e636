#!/usr/bin/env bash
# The README's headline reports: `evgate eval` on the test and test-ood splits of the
# simulator's suite v5 with the committed models (S, the model under test, then L when present),
# plus every model in models/ablation (ATC variants and sizes for tables VI and VII) when that
# folder holds any. Writes JSON, Markdown tables and plots into evidence/reports/test-v5 and
# evidence/reports/test-ood-v5. Environment: EVGATE_SUITE (default data/suite-v5), EVGATE_REPORTS (default
# evidence/reports), EVGATE_SPLITS (default "test test-ood"), EVGATE_WITH_L (default 1: include L when
# present); further arguments go to `evgate eval` (e.g. --threads 4, --max-seconds 2).
set -euo pipefail
cd "$(dirname "$0")/.."
suite=${EVGATE_SUITE:-data/suite-v5}
reports=${EVGATE_REPORTS:-evidence/reports}
read -r -a splits <<<"${EVGATE_SPLITS:-test test-ood}"
for split in "${splits[@]}"; do
  if [ ! -d "$suite/$split" ]; then
    echo "eval-report: no $split split at $suite/$split (generate it with" \
      "\`bash scripts/fetch-photos.sh && evgate sim suite --out $suite\` or set EVGATE_SUITE)" >&2
    exit 1
  fi
done
bash scripts/fetch-onnxruntime.sh
cargo build --release -p evgate
models=(--model models/evgate-S.onnx)
if [ "${EVGATE_WITH_L:-1}" = 1 ] && [ -f models/evgate-L.onnx ]; then
  models+=(--model models/evgate-L.onnx)
fi
if compgen -G "models/ablation/*.onnx" > /dev/null; then
  models+=(--ablation-models models/ablation)
fi
for split in "${splits[@]}"; do
  name="$split-v5"
  args=(--suite "$suite" --split "$split" --report "$reports/$name" "${models[@]}")
  echo "evgate eval ${args[*]} $*" >&2
  target/release/evgate eval "${args[@]}" "$@"
done
