"""Training-step time with the per-pair contrast-maximisation loop (before) and the batched
term (after), interleaved step by step on identical networks and batches; and the CM term alone
(forward + backward). Run from models/training/ under `taskset -c 1`; prints JSON."""

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path[:0] = [".", "tests"]
from test_contrast_maximisation import _contrast_by_pair_loop  # noqa: E402

from evgate_train.batches import ChunkSampler  # noqa: E402
from evgate_train.network import NetworkConfig, SuppressionNetwork  # noqa: E402
from evgate_train.objective import LossWeights, contrast_term, window_objective  # noqa: E402
from evgate_train.sequence import load_sequence  # noqa: E402


def step(network, optimiser, batches, weights, variant: str, last_only: bool, crop: int) -> float:
    started = time.perf_counter()
    states = network.initial_states(len(batches[0].future_events), crop, crop)
    total = 0.0
    for index, batch in enumerate(batches):
        out = network(batch.voxel, batch.horizons_ms, states)
        states = out.states
        with_contrast = variant != "none" and (not last_only or index == len(batches) - 1)
        if variant == "batched":
            terms = window_objective(out, batch, weights, with_contrast)
        else:
            terms = window_objective(out, batch, weights, with_contrast=False)
            if with_contrast:
                terms["total"] = terms["total"] + weights.contrast * _contrast_by_pair_loop(out.velocity, batch, weights)
        total = total + terms["total"] / len(batches)
    optimiser.zero_grad(set_to_none=True)
    total.backward()
    optimiser.step()
    return time.perf_counter() - started


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--sequence", type=Path, required=True)
    parser.add_argument("--size", default="S")
    parser.add_argument("--batch", type=int, default=4)
    parser.add_argument("--windows", type=int, default=4)
    parser.add_argument("--crop", type=int, default=160)
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--warmup", type=int, default=2)
    parser.add_argument("--last-window-only", action="store_true")
    args = parser.parse_args()
    torch.set_num_threads(1)
    sequence = load_sequence(args.sequence)
    sampler = ChunkSampler([sequence], args.windows, args.crop, 4000, augment=True, seed=7)
    drawn = [sampler.sample(args.batch) for _ in range(args.warmup + args.steps)]
    weights = LossWeights()
    networks, optimisers = [], []
    variants = ("loop", "batched", "none")
    for _ in variants:
        torch.manual_seed(7)
        networks.append(SuppressionNetwork(NetworkConfig(size=args.size)))
        optimisers.append(torch.optim.AdamW(networks[-1].parameters(), lr=2e-3))
    times = {name: [] for name in variants}
    for i, batches in enumerate(drawn):
        for name, network, optimiser in zip(variants, networks, optimisers):
            elapsed = step(network, optimiser, batches, weights, name, args.last_window_only, args.crop)
            if i >= args.warmup:
                times[name].append(elapsed)
        print(f"step {i + 1}/{len(drawn)}", file=sys.stderr)
    # The CM term alone, forward + backward, on a fixed velocity field of every window.
    term_times = {"loop": [], "batched": []}
    torch.manual_seed(0)
    pairs = 0
    for batches in drawn:
        for batch in batches:
            velocity = 0.1 * torch.randn(args.batch, batch.host_horizons_ms.shape[1], 2, args.crop, args.crop)
            pairs += 1
            for name in ("loop", "batched"):
                field = velocity.clone().requires_grad_(True)
                started = time.perf_counter()
                if name == "loop":
                    value = _contrast_by_pair_loop(field, batch, weights)
                else:
                    value = contrast_term(field, batch, weights)
                value.backward()
                term_times[name].append(time.perf_counter() - started)
    events = [len(e.x) for batches in drawn for b in batches for es in b.future_events for e in es]
    report = {
        "config": vars(args) | {"sequence": str(args.sequence), "threads": 1},
        "future_events_per_pair_mean": float(np.mean(events)),
        "step_s": {k: {"median": statistics.median(v), "mean": statistics.fmean(v)} for k, v in times.items()},
        "step_speedup_median": statistics.median(times["loop"]) / statistics.median(times["batched"]),
        "contrast_term_per_window_s": {
            k: {"median": statistics.median(v), "mean": statistics.fmean(v)} for k, v in term_times.items()
        },
        "contrast_term_speedup_median": statistics.median(term_times["loop"]) / statistics.median(term_times["batched"]),
        "contrast_term_windows": pairs,
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
