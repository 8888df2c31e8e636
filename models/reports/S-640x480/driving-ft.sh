#!/bin/bash
# S fine-tuned from the shipped weights (run 8 step 800) with driving sequences added: L's 36
# EVIMO-like training sequences + suite-v4's train driving-106000 + 8 new driving sequences
# (seeds 130000-130007, 3 s each), run 8's recipe, 400 steps.
set -e
cd "$(dirname "$0")/../../.."
link() { mkdir -p "data/lease-driving/train/$2"; ln -sf "$(realpath "$1")" "data/lease-driving/train/$2/sequence.npz"; }
for sequence in data/lease/train/*/; do link "$sequence/sequence.npz" "$(basename "$sequence")"; done
link data/suite-v4/train/driving-106000/sequence.npz driving-106000
for s in 130000 130001 130002 130003 130004 130005 130006 130007; do
  target/release/evgate sim --preset driving --seed $s --duration-s 3 --out data/driving-train/driving-$s
  link data/driving-train/driving-$s/sequence.npz driving-$s
done
cd models/training
.venv/bin/python -m evgate_train.manifest --data ../../data/lease-driving/train --output ../../data/lease-driving/manifest.json
PYTHONUNBUFFERED=1 .venv/bin/python -m evgate_train.train \
  --data ../../data/lease-driving/train --manifest ../../data/lease-driving/manifest.json \
  --run-dir runs/S-driving-ft --init-from runs/S5-chunk6/checkpoint-step800.pt \
  --steps 400 --lr 3e-4 --warmup 20 --crop 160 --batch 8 --chunk-windows 6 \
  --checkpoint-every 50 --positive-weight 3 --dice-weight 1.0 --flow-target arrival --flow-weight 0.2 \
  --contrast-last-window-only --threads 1 > runs/S-driving-ft.out 2>&1
