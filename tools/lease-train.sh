#!/usr/bin/env bash
# Trains one model on a leased GPU machine inside a fixed wall-clock budget, in one command:
# the simulator generates suite v5's train split (or its first PER_PRESET sequences of each
# preset) on every core, the network trains on CUDA until the budget is spent, its PyTorch CUDA
# latency is measured, and OUT receives the float32 weights (split into 15 MiB parts: the lease
# returns files of at most 16 MiB), the weight average where one is kept, and the logs.
#
#   bash tools/lease-train.sh OUT SECONDS [SIZE [TRAIN-ARGUMENTS...]]
#
# SECONDS is the whole command's budget; training gets what generation leaves minus a reserve
# for saving and timing, and its learning rate decays over that time (`--time-budget-s`).
# TRAIN-ARGUMENTS go to evgate_train.train after the script's own (the recipe: for example
# --event-jitter --positive-weight 1 --ema-decay 0.995 --data-workers 14). Needs
# target/release/evgate (built here, carried there) and a python3 with torch, numpy, scipy and
# tqdm. Reassemble the weights with `cat OUT/weights.pt.part-* > weights.pt`;
# `evgate_train.export` and `evaluate` read the file like any checkpoint (the weight average,
# OUT/ema.pt.part-*, likewise).
# Overrides (environment): DEVICE (cuda), STREAMS (32), WINDOWS_PER_STEP (4), STEPS (6000: the
# schedule's length; the budget may end it earlier), INIT_FROM (continue from these weights
# with a fresh optimiser), LR (1e-3), WARMUP (100), THREADS (4: torch threads of the trainer),
# PER_PRESET (40: the whole split), JOBS (the core count: sequences simulated at once),
# RESERVE_S (75: saving and timing), LATENCY (1; 0 skips the CUDA timing).
set -euo pipefail

usage="usage: lease-train.sh OUT SECONDS [SIZE [TRAIN-ARGUMENTS...]]"
out=${1:?$usage}
budget_s=${2:?$usage}
size=${3:-L}
shift $(($# < 3 ? $# : 3))
started=$(date +%s)
root=$(cd "$(dirname "$0")/.." && pwd)
evgate=${EVGATE_BIN:-$root/target/release/evgate}
python=${PYTHON:-python3}
device=${DEVICE:-cuda}
data_root=$root/data/lease
data=$data_root/train
run=$root/models/training/runs/lease-$size
mkdir -p "$data" "$run" "$out"
elapsed() { echo $(($(date +%s) - started)); }

nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader 2>/dev/null || echo "no nvidia-smi"
"$python" -c 'import torch; print("torch", torch.__version__, "cuda", torch.cuda.is_available())'

# Suite v5's train split, as the CPU campaign trains on, or its first sequences of each preset:
# as many as the disk holds with a margin (the 40 per preset of the whole split take 62.1 GB,
# 1.52 GiB for each sequence per preset).
free_kb=$(df -Pk "$data_root" | awk 'NR == 2 { print $4 }')
fits=$((free_kb * 85 / 100 / 1590000))
per_preset=$((${PER_PRESET:-40} < fits ? ${PER_PRESET:-40} : fits))
if ((per_preset < 1)); then
    echo "$((free_kb / 1048576)) GiB free in $data_root: too little for one sequence per preset" >&2
    exit 1
fi
echo "$((free_kb / 1048576)) GiB free: generating $per_preset sequences per preset"
"$evgate" sim suite --out "$data_root" --scale full --splits train --per-preset "$per_preset" \
    --jobs "${JOBS:-$(nproc)}" --json >"$out/suite-totals.json"
echo "generated $(find "$data" -name sequence.npz | wc -l) training sequences in $(elapsed) s"
sha256sum "$data_root/manifest.json"
cd "$root/models/training"

reserve_s=${RESERVE_S:-75}
train_s=$((budget_s - $(elapsed) - reserve_s))
echo "training $size on $device for $train_s s (loading included) from $(elapsed) s"
status=0
"$python" -m evgate_train.train --data "$data" --manifest "$data_root/manifest.json" --run-dir "$run" \
    --size "$size" --device "$device" --threads "${THREADS:-4}" --streams "${STREAMS:-32}" \
    --windows-per-step "${WINDOWS_PER_STEP:-4}" --steps "${STEPS:-6000}" \
    --time-budget-s "$train_s" --lr "${LR:-1e-3}" --warmup "${WARMUP:-100}" ${INIT_FROM:+--init-from "$INIT_FROM"} \
    --checkpoint-every 500 --seed 7 "$@" >"$run/train.out" 2>&1 || status=$?
tr '\r' '\n' <"$run/train.out" | grep -v '^\s*$' | tail -n 8
cp "$run/log.jsonl" "$run/config.json" "$out/" 2>/dev/null || true
if ((status != 0)); then
    tail -c 4000 "$run/train.out" >"$out/train-failure.txt"
    echo "training failed with status $status after $(elapsed) s"
    exit "$status"
fi
echo "trained in $(elapsed) s"

# Weights only (the optimiser state triples the size and is not needed to export or fine-tune).
"$python" - "$run/checkpoint.pt" "$run/weights.pt" <<'EOF'
import sys
import torch
payload = torch.load(sys.argv[1], map_location="cpu", weights_only=False)
payload["optimiser"] = None
torch.save(payload, sys.argv[2])
print("step", payload["step"], "manifest", payload["manifest_sha256"][:12])
EOF
sha256sum "$run/weights.pt"
split -b 15M -d "$run/weights.pt" "$out/weights.pt.part-"
if [[ -f $run/ema.pt ]]; then
    sha256sum "$run/ema.pt"
    split -b 15M -d "$run/ema.pt" "$out/ema.pt.part-"
fi

if [[ $device == cuda && ${LATENCY:-1} != 0 ]]; then
    "$python" -m evgate_train.torch_latency --checkpoint "$run/weights.pt" --device cuda \
        --inputs 346x260,640x480 --horizons 1,8 --output "$out/latency-cuda-tf32.json" >/dev/null
    "$python" -m evgate_train.torch_latency --checkpoint "$run/weights.pt" --device cuda --no-tf32 \
        --inputs 346x260,640x480 --horizons 1,8 --output "$out/latency-cuda-fp32.json" >/dev/null
    "$python" -c 'import json,sys
for f in sys.argv[1:]:
    r = json.load(open(f)); print(r["device"], r["precision"], [(x["input"], x["horizons"], x["median_ms"]) for x in r["results"]])' \
        "$out"/latency-cuda-*.json
fi
echo "done in $(elapsed) s"
