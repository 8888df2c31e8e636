#!/usr/bin/env bash
# The CPU training campaign of S on suite v5, resumable across machines: it continues
# models/campaign/<RUN>/checkpoint.pt (committed with its log.jsonl and val.jsonl) where the last
# machine stopped, regenerating the suite's train and val splits first where they are missing
# (bit-identical from the simulator's seeds). A run without a checkpoint yet starts from the
# weights of INIT_FROM.
#
#   bash models/training/campaign.sh            # from the repository root; low priority
#
# The recipe trains with event jitter (dropout, polarity flips, local rate scaling of the
# input) and a BCE positive weight of 1, each of which beat the recipe without it in a paired
# run on the final v5 val (mIoU at t + 100 ms +1.4 [0.4, 2.8] and +1.6 [1.1, 2.2]; model card).
# It keeps an exponential moving average of the weights (decay 0.999) in ema.pt beside the
# checkpoint, to choose on val between the averaged and the last weights. The shipped S is the
# average of run S-v5c-gates at the end of its 3000-step schedule peaking at 3e-4:
# run S-v5c-14k's average with 3x3 ConvGRU gates in every stage (the lever that gave current
# R@0.5 +0.6 [0.2, 0.9] in 600 steps, too little to ship alone). S-v5c-14k continued S-v5c-11k
# (the S before) from its step 10800 to 14000 and gained nothing on small val after step 10500.
# S-v5c-11k continued S-v5c-8k from its step 8000, which continued S-v5c-6k from 6000, which
# continued S-v5c-jitter-pos1 from 4000; at each jump the rate rose to where the longer schedule
# stands. Run S-v5c-gates-6k continued S-v5c-gates from its step 3000 to the end of a 6000-step
# schedule, and run S-v5c-s8 took its average 3000 steps further with 8 streams per step, not 4;
# neither average gained mIoU over S on full val, so neither shipped (model card). The default
# run, S-v5c-wide24, widened S-v5c-s8's average's encoder from base 16 to 24 (function-preserving
# at step 0) for 3000 steps of 8 streams (4.3 s each on 2 cores with val, not 3.6 s); its average
# gained pIoU and event F1 over S on full val but not mIoU, so it did not ship either (model
# card, the lever table). A further run needs a new RUN and INIT_FROM.
#
# Environment: RUN (S-v5c-wide24), INIT_FROM (../campaign/S-v5c-s8/ema.pt, relative to
# models/training, for a new RUN; empty: random weights), STEPS (3000: the schedule's length),
# STOP_AT (0: run to STEPS), THREADS (1), LR (3e-4: the peak rate), STREAMS (8: sequences per
# step; 4 for every run before S-v5c-s8), FIRST_SPATIAL_GRU_STAGE (0: 3x3 gates from the first
# stage; the runs before S-v5c-gates used LR=1e-3 and 2), ENCODER_BASE_CHANNELS (24; empty for
# base 16, every run before S-v5c-wide24). Extra arguments go to evgate_train.train.
set -euo pipefail

root=$(cd "$(dirname "$0")/../.." && pwd)
run=${RUN:-S-v5c-wide24}
init_from=${INIT_FROM-../campaign/S-v5c-s8/ema.pt}
encoder_base_channels=${ENCODER_BASE_CHANNELS-24}
steps=${STEPS:-3000}
evgate=$root/target/release/evgate
# A finished run would otherwise spend the 35 minutes of data generation before stopping at once.
log=$root/models/campaign/$run/log.jsonl
done_steps=$(tail -n 1 "$log" 2>/dev/null | grep -o '"step": [0-9]*' | grep -o '[0-9]*$' || true)
if (( ${done_steps:-0} >= steps )); then
    echo "campaign: run $run has done ${done_steps} of its $steps steps (models/campaign/$run/log.jsonl);" \
        "name a new RUN (with INIT_FROM) or a longer STEPS" >&2
    exit 1
fi
if [[ ! -f $root/data/suite-v5-full/manifest.json ]]; then
    # The split is 62.1 GB (docs/simulator.md); a full disk stops the simulator at the last
    # sequences, after 44 minutes, so refuse at once when it cannot fit.
    needed_kb=$((62200 * 1000 * 1000 / 1024))
    present_kb=$(du -sk "$root/data/suite-v5-full" 2>/dev/null | cut -f1 || true)
    free_kb=$(df -Pk "$root" | awk 'NR == 2 { print $4 }')
    if (( free_kb + ${present_kb:-0} < needed_kb )); then
        echo "campaign: the train split needs 62.2 GB in $root/data; $((free_kb * 1024 / 1000000000)) GB free" \
            "beside $((${present_kb:-0} * 1024 / 1000000000)) GB already there. Free space first (for" \
            "example cargo clean --profile dev; the release build runs the simulator)." >&2
        exit 1
    fi
    "$evgate" sim suite --out "$root/data/suite-v5-full" --scale full --splits train --jobs 2
fi
if [[ ! -d $root/data/suite-v5/val ]]; then
    "$evgate" sim suite --out "$root/data/suite-v5" --scale small --splits val
fi
cd "$root/models/training"
# Paths stay relative to models/training: the data cursor in the checkpoint names them.
exec nice -n 19 .venv/bin/python -m evgate_train.train \
    --data ../../data/suite-v5-full/train --manifest ../../data/suite-v5-full/manifest.json \
    --run-dir "../campaign/$run" --size S --steps "$steps" --lr "${LR:-3e-4}" \
    --streams "${STREAMS:-8}" \
    --first-spatial-gru-stage "${FIRST_SPATIAL_GRU_STAGE:-0}" \
    ${encoder_base_channels:+--encoder-base-channels "$encoder_base_channels"} --stop-at-step "${STOP_AT:-0}" \
    --threads "${THREADS:-1}" --val-data ../../data/suite-v5/val --val-every 500 \
    --checkpoint-every 100 --event-jitter --positive-weight 1 --ema-decay 0.999 --resume ${init_from:+--init-from "$init_from"} "$@"
