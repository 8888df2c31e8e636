"""Chooses the mask threshold (a logit) that maximises per-event F1 on validation sequences,
judging events the way evgate-gate does, with the exported graph evgate-infer runs.

    python -m evgate_train.calibrate --model ../evgate-S.onnx --data ../../data/suite-v5/val \
        --output runs/calibration.json

Each sequence streams from its start with the recurrent state carried. The forecast made at
reference time t, at the service's 8 default horizons (12.5, 25, ..., 100 ms), judges the events
of (t, t + 50 ms]: an event at t + d takes the mask whose interval holds d (the gate's midpoint
rule). An event is a true positive when kept and labelled as a moving object (events_label > 0).
Precision, recall and F1 are computed per sequence and averaged over sequences, as `evgate eval`
scores them, so that the threshold chosen is the one that maximises the reported figure; a
sequence with moving-object events where nothing is kept scores F1 0. The F1 of all events
pooled is reported beside it (`pooled-f1`). Writes the F1 curve over thresholds, the best
threshold and the figures at 0 as JSON.

`--dilations 0,1,2` also measures keep regions: each forecast's logits dilated by r pixels (a
maximum over the (2r + 1)-pixel square around each pixel, as evgate-infer applies
`evgate.keep-dilation-px`) before the lookup, and reports the best threshold per radius. The
report's `choice` is the mask threshold (the best undilated one) and the keep radius and
threshold of the best F1 over every radius measured; it prints them as
`evgate_train.export` flags.
"""

import argparse
import json
import logging
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from .onnx_network import load_export
from .sequence import SequenceFormatError, load_sequence
from .voxel import WINDOW_US, padded, voxel_grid

SERVICE_HORIZONS_MS = tuple(12.5 * k for k in range(1, 9))
THRESHOLDS = np.round(np.arange(-6.0, 6.0001, 0.05), 2)

log = logging.getLogger("evgate_train.calibrate")


class CalibrationError(ValueError):
    """Validation data that cannot be calibrated on: no sequences, or events without labels."""


def mask_index(d_us: np.ndarray, horizons_ms: tuple[float, ...]) -> np.ndarray:
    """The forecast mask of each event d µs after the reference time: mask k from the midpoint
    between horizons k - 1 and k (rounded up, as evgate-core's interval rule) on."""
    horizons_us = np.round(np.array(horizons_ms) * 1000).astype(np.int64)
    gaps = np.diff(horizons_us)
    starts = horizons_us[:-1] + gaps // 2 + gaps % 2
    return np.searchsorted(starts, d_us, side="right")


def sequence_size(path: Path) -> tuple[int, int]:
    """(width, height) of a sequence file, read without loading its arrays."""
    try:
        with np.load(path, allow_pickle=False) as archive:
            width, height = (int(v) for v in archive["resolution"])
    except (OSError, ValueError, KeyError) as error:
        raise CalibrationError(f"{path}: cannot read its resolution: {error}") from error
    return width, height


def dilated(mask_logits: torch.Tensor, radius: int) -> torch.Tensor:
    """[K, H, W] logits, each the maximum over the (2 radius + 1)-pixel square around it."""
    if radius == 0:
        return mask_logits
    return F.max_pool2d(mask_logits[None], 2 * radius + 1, stride=1, padding=radius)[0]


def event_logits(network, path: Path, radii: tuple[int, ...] = (0,)) -> tuple[dict[int, np.ndarray], np.ndarray]:
    """Per dilation radius, the logit of every event judged by a forecast of the sequence; and
    whether each event is a moving object."""
    sequence = load_sequence(path)
    if sequence.events_label is None:
        raise CalibrationError(f"{path}: no events_label array; calibration needs labelled events")
    states = network.initial_states(1, *network.input_size)
    horizons = torch.tensor([SERVICE_HORIZONS_MS], dtype=torch.float32)
    logits, positives = {radius: [] for radius in radii}, []
    for reference in sequence.ref_ts:
        t_end = int(reference)
        window = sequence.event_range(t_end - WINDOW_US, t_end + 1)
        voxel = voxel_grid(
            sequence.events_t[window], sequence.events_x[window], sequence.events_y[window],
            sequence.events_on[window], t_end, sequence.width, sequence.height,
        )
        out = network(torch.from_numpy(voxel)[None], horizons, states, network.warp_resolution)
        states = out.states
        following = sequence.event_range(t_end + 1, t_end + WINDOW_US + 1)
        d_us = sequence.events_t[following] - t_end
        index = mask_index(d_us, SERVICE_HORIZONS_MS)
        for radius in radii:
            masks = dilated(out.future_mask_logits[0], radius).numpy()
            logits[radius].append(masks[index, sequence.events_y[following], sequence.events_x[following]])
        positives.append(sequence.events_label[following] > 0)
    return {radius: np.concatenate(values) for radius, values in logits.items()}, np.concatenate(positives)


@dataclass
class SequenceCounts:
    """One sequence's events kept (logit above each threshold) and moving-object events among
    them, per threshold, and its moving-object events in all."""

    kept: np.ndarray
    true_positive: np.ndarray
    positive: int


def sequence_counts(logits: np.ndarray, positives: np.ndarray, thresholds: np.ndarray) -> SequenceCounts:
    order = np.argsort(logits)
    sorted_logits, sorted_positive = logits[order], positives[order]
    # Events at or below a threshold: the count from the left; kept ones are the rest.
    positive_below = np.concatenate([[0], np.cumsum(sorted_positive, dtype=np.int64)])
    below = np.searchsorted(sorted_logits, thresholds, side="right")
    positive = int(positive_below[-1])
    return SequenceCounts(len(logits) - below, positive - positive_below[below], positive)


def f1_curve(counts: list[SequenceCounts], thresholds: np.ndarray) -> list[dict]:
    """Per threshold, precision, recall and F1 averaged over the sequences where each is
    defined (precision where something is kept, recall and F1 where moving-object events
    occur), the F1 of all events pooled, and the events kept."""
    kept = np.stack([c.kept for c in counts]).astype(np.float64)
    true_positive = np.stack([c.true_positive for c in counts]).astype(np.float64)
    positive = np.array([c.positive for c in counts], dtype=np.float64)[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        precision = np.where(kept > 0, true_positive / kept, np.nan)
        recall = np.where(positive > 0, true_positive / positive, np.nan)
        f1 = np.where(positive > 0, np.where(kept > 0, 2 * true_positive / (kept + positive), 0.0), np.nan)
    pooled_kept, pooled_true = kept.sum(axis=0), true_positive.sum(axis=0)
    pooled_positive = float(positive.sum())
    rows = []
    for i, threshold in enumerate(thresholds):
        denominator = pooled_kept[i] + pooled_positive
        rows.append(
            {
                "threshold-logit": float(threshold),
                "precision": defined_mean(precision[:, i]),
                "recall": defined_mean(recall[:, i]),
                "f1": defined_mean(f1[:, i]),
                "pooled-f1": float(2 * pooled_true[i] / denominator) if denominator else 0.0,
                "kept": int(pooled_kept[i]),
            }
        )
    return rows


def defined_mean(values: np.ndarray) -> float:
    """The mean of the values that are defined; 0 when none is."""
    defined = values[~np.isnan(values)]
    return float(defined.mean()) if len(defined) else 0.0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", type=Path, required=True, help="exported .onnx network")
    parser.add_argument("--data", type=Path, required=True, help="validation .npz sequences (searched recursively)")
    parser.add_argument("--threads", type=int, default=1, help="ONNX Runtime threads")
    parser.add_argument("--output", type=Path, required=True, help="JSON report path")
    parser.add_argument(
        "--dilations",
        default="0",
        help="comma-separated dilation radii in pixels to measure besides 0 (the mask as the gate uses it)",
    )
    args = parser.parse_args(argv)
    radii = parse_radii(args.dilations)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    paths = sorted(args.data.rglob("*.npz"))
    if not paths:
        raise CalibrationError(f"{args.data}: no .npz sequences found")
    network = load_export(args.model, args.threads).network
    height, width = network.input_size
    counts, skipped = {radius: [] for radius in radii}, []
    events = moving_object_events = 0
    for path in tqdm(paths, desc="calibrate", unit="seq"):
        size = sequence_size(path)
        if padded(size[0]) != width or padded(size[1]) != height:
            # Another sensor size has its own export (e.g. driving's 640x480).
            log.info("%s: %dx%d does not pad to the export's %dx%d; left out", path, *size, width, height)
            skipped.append(str(path))
            continue
        try:
            sequence_logits, sequence_positives = event_logits(network, path, radii)
        except SequenceFormatError as error:
            raise CalibrationError(str(error)) from error
        for radius in radii:
            counts[radius].append(sequence_counts(sequence_logits[radius], sequence_positives, THRESHOLDS))
        events += len(sequence_positives)
        moving_object_events += int(sequence_positives.sum())
    if not counts[0]:
        raise CalibrationError(f"{args.data}: no sequence pads to the export's {width}x{height} input")
    by_radius = {}
    for radius in radii:
        radius_curve = f1_curve(counts.pop(radius), THRESHOLDS)
        by_radius[radius] = {
            "curve": radius_curve,
            "best": max(radius_curve, key=lambda row: row["f1"]),
            "at-zero": next(row for row in radius_curve if row["threshold-logit"] == 0.0),
        }
    curve, best, at_zero = by_radius[0]["curve"], by_radius[0]["best"], by_radius[0]["at-zero"]
    chosen_radius = max(by_radius, key=lambda radius: by_radius[radius]["best"]["f1"])
    chosen = by_radius[chosen_radius]["best"]
    choice = {
        "threshold-logit": best["threshold-logit"] + 0.0,
        "keep-threshold-logit": chosen["threshold-logit"] + 0.0,
        "keep-dilation-px": chosen_radius,
        **{key: chosen[key] for key in ("precision", "recall", "f1", "pooled-f1", "kept")},
    }
    report = {
        "model": str(args.model),
        "data": str(args.data),
        "sequences": [str(p) for p in paths if str(p) not in skipped],
        "left-out": skipped,
        "events": events,
        "moving-object-events": moving_object_events,
        "horizons-ms": list(SERVICE_HORIZONS_MS),
        "best": best,
        "at-zero": at_zero,
        "curve": curve,
        "choice": choice,
        "dilations": [
            {"dilation-px": radius, "best": entry["best"], "at-zero": entry["at-zero"]}
            for radius, entry in by_radius.items()
        ],
    }
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(report, indent=2))
    print(f"best {summary(best)}; at 0: F1 {at_zero['f1']:.3f}")
    for radius, entry in by_radius.items():
        if radius != 0:
            print(f"dilated {radius} px: best {summary(entry['best'])}")
    print(
        f"choice: --threshold-logit={choice['threshold-logit']:g} "
        f"--keep-threshold-logit={choice['keep-threshold-logit']:g} --keep-dilation-px {chosen_radius} "
        f"(F1 {choice['f1']:.3f})"
    )
    return 0


def summary(row: dict) -> str:
    return (
        f"threshold-logit {row['threshold-logit']:+.2f}: F1 {row['f1']:.3f} "
        f"(P {row['precision']:.3f}, R {row['recall']:.3f}; all events pooled: F1 {row['pooled-f1']:.3f})"
    )


def parse_radii(text: str) -> tuple[int, ...]:
    try:
        radii = tuple(int(part) for part in text.split(","))
    except ValueError as error:
        raise CalibrationError(f"--dilations {text!r}: expected comma-separated whole pixels, e.g. 0,1,2") from error
    if not radii or min(radii) < 0 or len(set(radii)) != len(radii):
        raise CalibrationError(f"--dilations {text!r}: radii must be distinct and at least 0, e.g. 0,1,2")
    # The undilated mask is what the gate uses: always measured, and reported at the top level.
    return (0, *(radius for radius in radii if radius != 0))


if __name__ == "__main__":
    sys.exit(main())
