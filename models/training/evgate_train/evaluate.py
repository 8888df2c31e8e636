"""Evaluates trained checkpoints on held-out sequences, with the paper's Table VI ablation.

    python -m evgate_train.evaluate --data ../../data/suite/test \
        --model full=runs/S/checkpoint.pt --model no-atc=runs/S-none/checkpoint.pt \
        --output runs/eval-test.json

Every sequence is streamed from its start with the recurrent state carried, as the runtime
does. At each 50 ms reference time t with ground truth, the current mask is scored against
the mask at t (mIoU, pIoU, SR@0.5, R@0.5) and each forecast against the mask at t + h. The
first model also yields the two forecast-free baselines: its current mask held still ("no
forecast") and moved by linear extrapolation of its masks ("linear"); and two oracles that no
runtime can make, its current mask moved per object by the true motion to t + h
("true-motion") and by the true past motion carried on ("true-kinematics", `true_motion`),
which bound what a better flow would give that mask.
"""

import argparse
import json
import logging
import math
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from .checkpoint import load_checkpoint
from .flow_forecasts import rigid_forecast, splat_forecast
from .linear_extrapolation import extrapolate
from .metrics import SequenceScores, frame_scores
from .network import WARP_RESOLUTIONS, NetworkConfig, SuppressionNetwork
from .network_input import network_input
from .onnx_network import OnnxNetwork, load_export
from .sequence import Sequence, load_sequence
from .true_motion import true_history, true_kinematics_forecast, true_motion_forecast
from .voxel import WINDOW_US, padded

EVIMO_LIKE = ("boxes", "floor", "wall", "table", "fast")
log = logging.getLogger("evgate_train.evaluate")


class EvaluationSetupError(ValueError):
    """A bad --model specification or an empty data directory."""


def parse_model(spec: str) -> tuple[str, Path]:
    name, separator, path = spec.partition("=")
    if not separator or not name or not path:
        raise EvaluationSetupError(
            f"--model {spec!r}: expected NAME=CHECKPOINT or NAME=EXPORT.onnx, e.g. full=runs/S/checkpoint.pt"
        )
    return name, Path(path)


@torch.no_grad()
def evaluate_sequence(
    network: SuppressionNetwork | OnnxNetwork,
    sequence: Sequence,
    horizons_ms: list[float],
    with_baselines: bool,
    max_seconds: float = 0.0,
    warp_resolution: str = "full",
    flow_variants: bool = False,
) -> dict[str, SequenceScores]:
    """Scores keyed "current", "future-<h>ms" (and with the baselines "no-forecast-<h>ms",
    "linear-<h>ms", "true-motion-<h>ms", "true-kinematics-<h>ms"; with
    `flow_variants`, "rigid-<h>ms" and "splat-<h>ms" of `flow_forecasts`); `warp_resolution` as
    the network's (an export's default is "half")."""
    network.eval()
    # An export takes what the runtime builds: the default input.
    input_config = network.config if isinstance(network, SuppressionNetwork) else NetworkConfig()
    height, width = padded(sequence.height), padded(sequence.width)
    states = network.initial_states(1, height, width)
    horizons = torch.tensor([horizons_ms], dtype=torch.float32)
    scores: dict[str, SequenceScores] = defaultdict(SequenceScores)
    previous = None
    for reference in sequence.ref_ts:
        t_end = int(reference)
        if max_seconds > 0 and t_end - int(sequence.ref_ts[0]) >= max_seconds * 1e6:
            break
        window = sequence.event_range(t_end - WINDOW_US, t_end + 1)
        ts, xs, ys, on = (a[window] for a in (sequence.events_t, sequence.events_x, sequence.events_y, sequence.events_on))
        voxel = network_input(ts, xs, ys, on, t_end, sequence.width, sequence.height, input_config)
        out = network(torch.from_numpy(voxel)[None], horizons, states, warp_resolution=warp_resolution)
        states = out.states
        current = (out.mask_logits[0, 0, : sequence.height, : sequence.width] > 0).numpy()
        now = sequence.grid_index(t_end)
        if now is not None:
            event_pixels = sequence.event_pixels(t_end - WINDOW_US, t_end + 1)
            scores["current"].add(frame_scores(current, sequence.masks[now], event_pixels))
        for k, horizon in enumerate(horizons_ms):
            future = sequence.grid_index(t_end + int(round(horizon * 1000)))
            if future is None:
                continue
            truth = sequence.masks[future]
            forecast = (out.future_mask_logits[0, k, : sequence.height, : sequence.width] > 0).numpy()
            scores[f"future-{horizon:g}ms"].add(frame_scores(forecast, truth, None))
            if flow_variants:
                flow = out.future_flow[0, k, :, : sequence.height, : sequence.width].numpy()
                scores[f"rigid-{horizon:g}ms"].add(frame_scores(rigid_forecast(current, flow), truth, None))
                scores[f"splat-{horizon:g}ms"].add(frame_scores(splat_forecast(current, flow), truth, None))
            if with_baselines:
                scores[f"no-forecast-{horizon:g}ms"].add(frame_scores(current, truth, None))
                moved = extrapolate(previous, current, WINDOW_US / 1000, horizon) if previous is not None else current
                scores[f"linear-{horizon:g}ms"].add(frame_scores(moved, truth, None))
                if now is not None:
                    oracle = true_motion_forecast(current, sequence.masks[now], truth)
                    scores[f"true-motion-{horizon:g}ms"].add(frame_scores(oracle, truth, None))
                    history = true_history(sequence, t_end)
                    if history is not None:
                        oracle = true_kinematics_forecast(current, history, horizon)
                        scores[f"true-kinematics-{horizon:g}ms"].add(frame_scores(oracle, truth, None))
        previous = current
    return scores


def aggregate(per_sequence: list[tuple[str, dict[str, dict]]]) -> dict:
    """Means per preset (over its sequences) and over the EVIMO-like presets."""
    by_preset: dict[str, dict[str, list[dict]]] = defaultdict(lambda: defaultdict(list))
    for preset, summaries in per_sequence:
        for key, summary in summaries.items():
            by_preset[preset][key].append(summary)

    def mean_of(summaries: list[dict]) -> dict:
        metrics = [m for m in summaries[0] if m != "frames"]
        result = {"sequences": len(summaries), "frames": sum(s["frames"] for s in summaries)}
        for metric in metrics:
            values = [s[metric] for s in summaries if not math.isnan(s[metric])]
            result[metric] = float(np.mean(values)) if values else float("nan")
        return result

    presets = {preset: {key: mean_of(v) for key, v in keys.items()} for preset, keys in sorted(by_preset.items())}
    evimo = [p for p in EVIMO_LIKE if p in presets]
    keys = sorted({key for p in evimo for key in presets[p]})
    evimo_mean = {}
    for key in keys:
        rows = [presets[p][key] for p in evimo if key in presets[p]]
        evimo_mean[key] = {
            metric: float(np.nanmean([r[metric] for r in rows])) if any(not math.isnan(r[metric]) for r in rows) else float("nan")
            for metric in rows[0]
            if metric not in ("sequences", "frames")
        }
    return {"presets": presets, "evimo-like-mean": evimo_mean, "evimo-like-presets": evimo}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, required=True, help="directory searched recursively for .npz sequences")
    parser.add_argument(
        "--model",
        action="append",
        required=True,
        help="NAME=CHECKPOINT or NAME=EXPORT.onnx (run through ONNX Runtime as exported); repeatable; the first "
        "also gives the baselines",
    )
    parser.add_argument("--horizons-ms", default="100", help="comma-separated forecast horizons to score (ms)")
    parser.add_argument("--presets", default="", help="comma-separated presets to keep (default: all)")
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    parser.add_argument("--max-seconds", type=float, default=0.0, help="score only the leading seconds (0 = all)")
    parser.add_argument(
        "--warp-resolution",
        choices=WARP_RESOLUTIONS,
        default="full",
        help="where a checkpoint's future mask logits are warped: full (training) or half (what an export does by "
        "default); an .onnx model keeps the warp it was exported with",
    )
    parser.add_argument(
        "--flow-variants",
        action="store_true",
        help="also score each model's current mask moved by its flow without backward warping: rigidly per "
        "component (median flow) and by forward splatting (keys rigid-<h>ms, splat-<h>ms)",
    )
    parser.add_argument("--output", type=Path, required=True, help="JSON report path")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    torch.set_num_threads(args.threads)
    models = [parse_model(spec) for spec in args.model]
    horizons = [float(h) for h in args.horizons_ms.split(",")]
    paths = sorted(args.data.rglob("*.npz"))
    if not paths:
        raise EvaluationSetupError(f"{args.data}: no .npz sequences found")
    keep = {p for p in args.presets.split(",") if p}
    report: dict = {
        "data": str(args.data),
        "horizons_ms": horizons,
        "warp_resolution": args.warp_resolution,
        "models": {},
        "sequences": [str(p) for p in paths],
    }
    networks = [
        (name, load_export(path, args.threads) if path.suffix == ".onnx" else load_checkpoint(path)) for name, path in models
    ]

    exports = [name for name, checkpoint in networks if isinstance(checkpoint.network, OnnxNetwork)]
    if args.flow_variants and exports:
        raise EvaluationSetupError(
            f"--flow-variants needs the full-resolution flow of a checkpoint; {', '.join(exports)} is an export"
        )

    def warp_resolution_of(checkpoint) -> str:
        network = checkpoint.network
        return network.warp_resolution if isinstance(network, OnnxNetwork) else args.warp_resolution

    results: dict[str, list] = defaultdict(list)
    # Kept for paired comparisons between models (`paired_comparison`).
    per_sequence: dict[str, list] = defaultdict(list)
    for path in tqdm(paths, desc="evaluate", unit="seq"):
        sequence = load_sequence(path)
        if keep and sequence.preset not in keep:
            continue
        for index, (name, checkpoint) in enumerate(networks):
            scores = evaluate_sequence(
                checkpoint.network,
                sequence,
                horizons,
                with_baselines=index == 0,
                max_seconds=args.max_seconds,
                warp_resolution=warp_resolution_of(checkpoint),
                flow_variants=args.flow_variants,
            )
            summaries = {key: s.summary() for key, s in scores.items()}
            results[name].append((sequence.preset, summaries))
            per_sequence[name].append({"sequence": str(path), "preset": sequence.preset, "scores": summaries})
    for name, checkpoint in networks:
        report["models"][name] = {
            "checkpoint": str(dict(models)[name]),
            "warp_resolution": warp_resolution_of(checkpoint),
            "steps": checkpoint.step,
            "time-conditioning": checkpoint.network.config.time_conditioning,
            "size": checkpoint.network.config.size,
            **aggregate(results[name]),
            "per-sequence": per_sequence[name],
        }
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(report, indent=2))
    for name, model in report["models"].items():
        for key, metrics in model["evimo-like-mean"].items():
            text = " ".join(f"{m}={100 * v:.1f}%" for m, v in metrics.items())
            print(f"{name:>14} {key:>18} {text}")
    log.info("wrote %s", args.output)
    return 0


if __name__ == "__main__":
    sys.exit(main())
