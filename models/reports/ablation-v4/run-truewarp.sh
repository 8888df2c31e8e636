#!/bin/bash
# Control for the true-mask warp term: the position-aware ablation row's recipe plus the term.
cd "$(dirname "$0")/.."
while pgrep -f "runs/ablation-v4.sh" > /dev/null; do sleep 20; done
PYTHONPATH=runs/ablation-v4-code PYTHONUNBUFFERED=1 .venv/bin/python -m evgate_train.train \
  --data ../../data/lease/train --manifest ../../data/lease/manifest.json \
  --run-dir runs/ablation-v4/S-position-aware-truewarp --init-from runs/S5-chunk6/checkpoint-step800.pt \
  --steps 400 --lr 3e-4 --warmup 20 --crop 160 --batch 8 --chunk-windows 6 \
  --checkpoint-every 50 --positive-weight 3 --dice-weight 1.0 --flow-target arrival --flow-weight 0.2 \
  --contrast-last-window-only --true-mask-warp-weight 1.0 --threads 1 > runs/ablation-v4/S-position-aware-truewarp.out 2>&1
