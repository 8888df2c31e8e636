"""Chooses the mask threshold (a logit) that maximises per-event F1 on validation sequences,
judging events the way evgate-gate does, with the exported graph evgate-infer runs.

    python -m evgate_train.calibrate --model ../evgate-S.onnx --data ../../data/suite-v5/val \
        --output runs/calibration.json

Each sequence streams from its start with the recurrent state carried. The forecast made at
reference time t, at the service's 8 default horizons (12.5, 25, ..., 100 ms), judges the events
of (t, t + 50 ms]: an event at t + d takes the mask whose interval holds d (the gate's midpoint
rule). An event is a true positive when kept and labelled as a moving object (events_label > 0).
Writes the F1 curve over thresholds, the best threshold and the figures at 0 as JSON; pass the
threshold to `evgate_train.export --threshold-logit`.
"""

import argparse
import json
import logging
import sys
from pathlib import Path

import numpy as np
import torch
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


def event_logits(network, path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(logit, is a moving object) of every event judged by a forecast of the sequence."""
    sequence = load_sequence(path)
    if sequence.events_label is None:
        raise CalibrationError(f"{path}: no events_label array; calibration needs labelled events")
    states = network.initial_states(1, *network.input_size)
    horizons = torch.tensor([SERVICE_HORIZONS_MS], dtype=torch.float32)
    logits, positives = [], []
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
        masks = out.future_mask_logits[0].numpy()
        index = mask_index(d_us, SERVICE_HORIZONS_MS)
        logits.append(masks[index, sequence.events_y[following], sequence.events_x[following]])
        positives.append(sequence.events_label[following] > 0)
    return np.concatenate(logits), np.concatenate(positives)


def f1_curve(logits: np.ndarray, positives: np.ndarray, thresholds: np.ndarray) -> list[dict]:
    """Precision, recall and F1 of keeping the events whose logit exceeds each threshold."""
    order = np.argsort(logits)
    sorted_logits, sorted_positive = logits[order], positives[order]
    # Events at or below a threshold: the count from the left; kept ones are the rest.
    positive_below = np.concatenate([[0], np.cumsum(sorted_positive)])
    total_positive = int(positive_below[-1])
    rows = []
    for threshold in thresholds:
        below = int(np.searchsorted(sorted_logits, threshold, side="right"))
        kept = len(logits) - below
        true_positive = total_positive - int(positive_below[below])
        precision = true_positive / kept if kept else 0.0
        recall = true_positive / total_positive if total_positive else 0.0
        f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
        rows.append(
            {"threshold-logit": float(threshold), "precision": precision, "recall": recall, "f1": f1, "kept": kept}
        )
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", type=Path, required=True, help="exported .onnx network")
    parser.add_argument("--data", type=Path, required=True, help="validation .npz sequences (searched recursively)")
    parser.add_argument("--threads", type=int, default=1, help="ONNX Runtime threads")
    parser.add_argument("--output", type=Path, required=True, help="JSON report path")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    paths = sorted(args.data.rglob("*.npz"))
    if not paths:
        raise CalibrationError(f"{args.data}: no .npz sequences found")
    network = load_export(args.model, args.threads).network
    height, width = network.input_size
    logits, positives, skipped = [], [], []
    for path in tqdm(paths, desc="calibrate", unit="seq"):
        size = sequence_size(path)
        if padded(size[0]) != width or padded(size[1]) != height:
            # Another sensor size has its own export (e.g. driving's 640x480).
            log.info("%s: %dx%d does not pad to the export's %dx%d; left out", path, *size, width, height)
            skipped.append(str(path))
            continue
        try:
            sequence_logits, sequence_positives = event_logits(network, path)
        except SequenceFormatError as error:
            raise CalibrationError(str(error)) from error
        logits.append(sequence_logits)
        positives.append(sequence_positives)
    if not logits:
        raise CalibrationError(f"{args.data}: no sequence pads to the export's {width}x{height} input")
    all_logits, all_positives = np.concatenate(logits), np.concatenate(positives)
    curve = f1_curve(all_logits, all_positives, THRESHOLDS)
    best = max(curve, key=lambda row: row["f1"])
    at_zero = next(row for row in curve if row["threshold-logit"] == 0.0)
    report = {
        "model": str(args.model),
        "data": str(args.data),
        "sequences": [str(p) for p in paths if str(p) not in skipped],
        "left-out": skipped,
        "events": int(len(all_logits)),
        "moving-object-events": int(all_positives.sum()),
        "horizons-ms": list(SERVICE_HORIZONS_MS),
        "best": best,
        "at-zero": at_zero,
        "curve": curve,
    }
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(report, indent=2))
    print(
        f"best threshold-logit {best['threshold-logit']:+.2f}: F1 {best['f1']:.3f} (P {best['precision']:.3f}, "
        f"R {best['recall']:.3f}); at 0: F1 {at_zero['f1']:.3f}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
