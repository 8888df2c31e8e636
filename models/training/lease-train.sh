#!/usr/bin/env bash
# Trains one model on a leased GPU machine inside a fixed wall-clock budget, in one command:
# the simulator generates the training sequences on every core, the network trains on CUDA until
# the budget is spent, its PyTorch CUDA latency is measured, and OUT receives the float32 weights
# (split into 15 MiB parts: the lease returns files of at most 16 MiB) with the logs.
#
#   bash models/training/lease-train.sh OUT SECONDS [SIZE]
#
# SECONDS is the whole command's budget; training gets what generation leaves minus a reserve
# for saving and timing. Needs target/release/evgate (built here, carried there) and a python3
# with torch, numpy, scipy and tqdm. Reassemble the weights with `cat OUT/weights.pt.part-* >
# weights.pt`; `evgate_train.export` and `evaluate` read the file like any checkpoint.
# Overrides (environment): DEVICE (cuda), SEQUENCES_PER_PRESET (6: the suite-v4 train seeds
# 10p000-10p001 and 10p002 onwards), BATCH (16), CHUNK_WINDOWS (6), LOADER_WORKERS (cores - 4),
# INIT_FROM (continue from these weights with a fresh optimiser), LR (1e-3), WARMUP (100),
# RESERVE_S (75: saving and timing), LATENCY (1; 0 skips the CUDA timing).
set -euo pipefail

out=${1:?usage: lease-train.sh OUT SECONDS [SIZE]}
budget_s=${2:?usage: lease-train.sh OUT SECONDS [SIZE]}
size=${3:-L}
started=$(date +%s)
root=$(cd "$(dirname "$0")/../.." && pwd)
evgate=${EVGATE_BIN:-$root/target/release/evgate}
python=${PYTHON:-python3}
device=${DEVICE:-cuda}
per_preset=${SEQUENCES_PER_PRESET:-6}
cores=$(nproc)
workers=${LOADER_WORKERS:-$((cores > 6 ? cores - 4 : 2))}
data=$root/data/lease/train
run=$root/models/training/runs/lease-$size
mkdir -p "$data" "$run" "$out"
elapsed() { echo $(($(date +%s) - started)); }

nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader 2>/dev/null || echo "no nvidia-smi"
"$python" -c 'import torch; print("torch", torch.__version__, "cuda", torch.cuda.is_available())'

# One simulator per core, pinned, so each runs single-threaded without oversubscription.
presets=(boxes floor wall table fast tabletop)
jobs=()
for index in "${!presets[@]}"; do
    for i in $(seq 0 $((per_preset - 1))); do
        jobs+=("${presets[$index]}:$((100000 + index * 1000 + i))")
    done
done
pin() { if command -v taskset >/dev/null; then taskset -c "$1" "${@:2}"; else "${@:2}"; fi; }
generate_share() {
    local core=$1 n=0 job
    for job in "${jobs[@]}"; do
        if ((n % cores == core)); then
            local preset=${job%%:*} seed=${job##*:}
            pin "$core" "$evgate" sim --preset "$preset" --seed "$seed" --duration-s 3 \
                --out "$data/$preset-$seed" --json >"$data/$preset-$seed.json"
        fi
        n=$((n + 1))
    done
}
pids=()
for core in $(seq 0 $((cores - 1))); do
    generate_share "$core" &
    pids+=($!)
done
for pid in "${pids[@]}"; do wait "$pid"; done
echo "generated ${#jobs[@]} sequences in $(elapsed) s"
cat "$data"/*.json >"$out/sequences.jsonl"

cd "$root/models/training"
"$python" -m evgate_train.manifest --data "$data" --output "$out/manifest.json"
sha256sum "$out/manifest.json"

reserve_s=${RESERVE_S:-75}
train_s=$((budget_s - $(elapsed) - reserve_s))
echo "training $size on $device for $train_s s (loading included) from $(elapsed) s"
status=0
"$python" -m evgate_train.train --data "$data" --manifest "$out/manifest.json" --run-dir "$run" \
    --size "$size" --device "$device" --loader-workers "$workers" --threads 4 \
    --batch "${BATCH:-16}" --chunk-windows "${CHUNK_WINDOWS:-6}" --crop 160 --steps 100000 \
    --time-budget-s "$train_s" --lr "${LR:-1e-3}" --warmup "${WARMUP:-100}" ${INIT_FROM:+--init-from "$INIT_FROM"} --positive-weight 3 --dice-weight 1 \
    --flow-target arrival --flow-weight 0.2 --contrast-last-window-only --checkpoint-every 500 \
    --seed 7 >"$run/train.out" 2>&1 || status=$?
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
