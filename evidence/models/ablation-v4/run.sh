#!/bin/bash
# Ablation rows fine-tuned from run 8's step-800 weights, run 8's recipe, 400 equal steps each.
cd "$(dirname "$0")/.."
for variant in position-aware reference none; do
  PYTHONPATH=runs/ablation-v4-code PYTHONUNBUFFERED=1 .venv/bin/python -m evgate_train.train \
    --data ../../data/lease/train --manifest ../../data/lease/manifest.json \
    --run-dir runs/ablation-v4/S-$variant --init-from runs/S5-chunk6/checkpoint-step800.pt \
    --init-time-conditioning $variant --steps 400 --lr 3e-4 --warmup 20 --crop 160 --batch 8 --chunk-windows 6 \
    --checkpoint-every 50 --positive-weight 3 --dice-weight 1.0 --flow-target arrival --flow-weight 0.2 \
    --contrast-last-window-only --threads 1 > runs/ablation-v4/S-$variant.out 2>&1 || exit 1
done
