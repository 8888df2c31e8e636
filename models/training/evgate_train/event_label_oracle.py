"""How much of the current IMO mask the events themselves show: the ground-truth mask at each
reference time t scored (as `evaluate` scores a model's current mask) against the pixels of the
events labelled IMO in the last S ms before t, dilated r times by the 4-connected cross (a
diamond of radius r, not the keep rule's square).

    python -m evgate_train.event_label_oracle --data ../../data/suite-v5-full-eval/val \\
        --output runs/event-label-oracle-val.json

The oracle knows every event's label, which no model does, but it sees only where events fell:
object interiors without texture stay empty, and a long span smears a moving object over its
trail. A model's current mask above the oracle's IMO IoU is filling in what the events leave out.

With `--horizons-ms`, each oracle mask and the ground-truth mask at t are also carried to t + h
and scored against the true mask there (`true_motion`): held still ("held"), moved per object by
its true past kinematics ("true-kinematics", what a forecast made at t could know at best) and by
its true displacement ("true-motion", which no forecast made at t can know). They bound what a
model's forecast can reach on the same data.

    python -m evgate_train.event_label_oracle --data ../../data/suite-v5-full-eval/val \
        --spans-ms 10 --dilations-px 4 --horizons-ms 100
"""

import argparse
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
from scipy import ndimage
from tqdm import tqdm

from .evaluate import aggregate
from .metrics import SequenceScores, frame_scores
from .sequence import Sequence, SequenceFormatError, load_sequence
from .timings import print_and_save
from .true_motion import true_history, true_kinematics_forecast, true_motion_forecast
from .voxel import WINDOW_US

SPANS_MS = (5, 10, 20, 50)
DILATIONS_PX = (0, 1, 2, 4, 8)
GROUND_TRUTH = "ground-truth"


class OracleInputError(ValueError):
    """A sequence without per-event labels, a span, dilation or horizon out of range, or a horizon
    off the ground-truth grid."""


def oracle_key(span_ms: int, dilation_px: int) -> str:
    return f"labelled-{span_ms}ms-r{dilation_px}"


def forecast_key(mask_key: str, forecast: str, horizon_ms: int) -> str:
    """`mask_key` is an `oracle_key` or `GROUND_TRUTH`; `forecast` is "held", "true-kinematics" or
    "true-motion"."""
    return f"{mask_key}-{forecast}-{horizon_ms}ms"


def score_sequence(
    sequence: Sequence, spans_ms: list[int], dilations_px: list[int], horizons_ms: list[int] = ()
) -> dict[str, SequenceScores]:
    if sequence.events_label is None:
        raise OracleInputError(f"{sequence.path}: no events_label array; the oracle needs each event's label")
    grid_ms = int(sequence.gt_ts[1] - sequence.gt_ts[0]) // 1000 if len(sequence.gt_ts) > 1 else 0
    off_grid = [h for h in horizons_ms if not grid_ms or h % grid_ms]
    if off_grid:
        raise OracleInputError(
            f"{sequence.path}: --horizons-ms {off_grid[0]} is not a multiple of the ground-truth grid's "
            f"{grid_ms} ms step"
        )
    scores: dict[str, SequenceScores] = defaultdict(SequenceScores)
    for reference in sequence.ref_ts:
        t_end = int(reference)
        now = sequence.grid_index(t_end)
        if now is None:
            continue
        event_pixels = sequence.event_pixels(t_end - WINDOW_US, t_end + 1)
        masks = {GROUND_TRUTH: sequence.masks[now] > 0}
        for span_ms in spans_ms:
            span = sequence.event_range(t_end - span_ms * 1000, t_end + 1)
            labelled = sequence.events_label[span] > 0
            imo_pixels = np.zeros_like(event_pixels)
            imo_pixels[sequence.events_y[span][labelled], sequence.events_x[span][labelled]] = True
            for dilation_px in dilations_px:
                predicted = ndimage.binary_dilation(imo_pixels, iterations=dilation_px) if dilation_px else imo_pixels
                scores[oracle_key(span_ms, dilation_px)].add(frame_scores(predicted, sequence.masks[now], event_pixels))
                masks[oracle_key(span_ms, dilation_px)] = predicted
        history = true_history(sequence, t_end)
        for horizon_ms in horizons_ms:
            future = sequence.grid_index(t_end + horizon_ms * 1000)
            if future is None:
                continue
            truth = sequence.masks[future]
            for mask_key, mask in masks.items():
                forecasts = {"held": mask, "true-motion": true_motion_forecast(mask, sequence.masks[now], truth)}
                if history is not None:
                    forecasts["true-kinematics"] = true_kinematics_forecast(mask, history, horizon_ms)
                for forecast, moved in forecasts.items():
                    scores[forecast_key(mask_key, forecast, horizon_ms)].add(frame_scores(moved, truth, None))
    return dict(scores)


def parse_list(flag: str, value: str, low: int, high: int) -> list[int]:
    try:
        values = [int(v) for v in value.split(",") if v]
    except ValueError:
        raise OracleInputError(f"{flag} {value!r}: expected comma-separated integers") from None
    bad = [v for v in values if not low <= v <= high]
    if not values or bad:
        raise OracleInputError(f"{flag} {value!r}: each value must be {low} to {high}")
    return values


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, required=True, help="directory searched recursively for .npz sequences")
    parser.add_argument(
        "--spans-ms", default=",".join(map(str, SPANS_MS)), help="comma-separated spans before t, 1 to 50 ms"
    )
    parser.add_argument(
        "--dilations-px", default=",".join(map(str, DILATIONS_PX)), help="comma-separated 4-connected dilation radii, 0 to 32 px"
    )
    parser.add_argument(
        "--horizons-ms",
        default="",
        help="comma-separated horizons, 10 to 100 ms on the ground-truth grid, at which the oracle and the "
        "ground-truth masks are also scored held, and moved by true kinematics and by true motion (none by default)",
    )
    parser.add_argument("--output", type=Path, help="also write the report as JSON here")
    args = parser.parse_args(argv)
    try:
        spans = parse_list("--spans-ms", args.spans_ms, 1, WINDOW_US // 1000)
        dilations = parse_list("--dilations-px", args.dilations_px, 0, 32)
        horizons = parse_list("--horizons-ms", args.horizons_ms, 10, 100) if args.horizons_ms else []
        paths = sorted(args.data.rglob("*.npz"))
        if not paths:
            raise OracleInputError(f"{args.data}: no .npz sequences found")
        per_sequence = []
        for path in tqdm(paths, desc="oracle", unit="seq"):
            sequence = load_sequence(path)
            summaries = {key: s.summary() for key, s in score_sequence(sequence, spans, dilations, horizons).items()}
            per_sequence.append((sequence.preset, summaries))
    except (OracleInputError, SequenceFormatError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    report = {
        "data": str(args.data),
        "spans-ms": spans,
        "dilations-px": dilations,
        "horizons-ms": horizons,
        **aggregate(per_sequence),
    }
    print_and_save(report, args.output)
    return 0


if __name__ == "__main__":
    sys.exit(main())
