"""Segmentation metrics of DESIGN.md section 4 (the same definitions as evgate-eval).

Prediction = logit > 0. IMO and background IoU, mIoU = their NaN-aware mean, pIoU = IMO IoU
over the pixels that hold at least one event, SR@0.5 = frames with IMO IoU >= 0.5 (a frame
with no IMO in prediction and truth counts as a success), R@0.5 = ground-truth instances
matched (Hungarian on IoU against 8-connected predicted components) with IoU > 0.5.

Also (this module only): R@0.5 of small, medium and large instances (`INSTANCE_AREA_BANDS`);
the predicted IMO area, false negatives and false positives as shares of the true IMO area,
pooled over a sequence's frames; they tell a forecast that is too large (e.g. smeared over the
strip a moving object uncovers) from one that is too small. The false positives farther than
`NEAR_TRUTH_PX` from every true IMO pixel are counted apart: objects seen where there are none,
not an object's outline drawn too wide.
"""

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.optimize import linear_sum_assignment

EIGHT_CONNECTED = np.ones((3, 3), dtype=bool)
# R@0.5 is also reported per band of instance area (px): the suite's objects are small, and how
# many are found depends most on their size. (name, smallest area, first area above the band)
INSTANCE_AREA_BANDS = (("small", 0, 200), ("medium", 200, 800), ("large", 800, None))
NEAR_TRUTH_PX = 5


def _near(truth: np.ndarray) -> np.ndarray:
    """The pixels within NEAR_TRUTH_PX (in x and y) of a true pixel: a square dilation, as a
    separable maximum filter (a twentieth of binary_dilation's time at 346x260)."""
    return ndimage.maximum_filter(truth, size=2 * NEAR_TRUTH_PX + 1, mode="constant", cval=False)


def _iou(predicted: np.ndarray, truth: np.ndarray) -> float:
    union = np.count_nonzero(predicted | truth)
    return np.count_nonzero(predicted & truth) / union if union else float("nan")


@dataclass
class FrameScores:
    imo_iou: float
    background_iou: float
    miou: float
    piou: float
    success: bool
    predicted_px: int
    truth_px: int
    false_negative_px: int
    false_positive_px: int
    false_positive_far_px: int  # more than NEAR_TRUTH_PX (in x or y) from every true IMO pixel
    instances: list[tuple[int, bool]]  # (area in px, found) of each ground-truth instance


def frame_scores(predicted: np.ndarray, truth_ids: np.ndarray, event_pixels: np.ndarray | None) -> FrameScores:
    """predicted: bool [H, W]; truth_ids: object ids [H, W]; event_pixels: bool [H, W] or None."""
    truth = truth_ids > 0
    imo = _iou(predicted, truth)
    background = _iou(~predicted, ~truth)
    defined = [v for v in (imo, background) if not np.isnan(v)]
    piou = _iou(predicted & event_pixels, truth & event_pixels) if event_pixels is not None else float("nan")
    instances = matched_instances(predicted, truth_ids)
    return FrameScores(
        imo_iou=imo,
        background_iou=background,
        miou=float(np.mean(defined)) if defined else float("nan"),
        piou=piou,
        success=bool(np.isnan(imo) or imo >= 0.5),
        predicted_px=int(np.count_nonzero(predicted)),
        truth_px=int(np.count_nonzero(truth)),
        false_negative_px=int(np.count_nonzero(truth & ~predicted)),
        false_positive_px=int(np.count_nonzero(predicted & ~truth)),
        false_positive_far_px=int(np.count_nonzero(predicted & ~_near(truth))),
        instances=instances,
    )


def matched_instances(
    predicted: np.ndarray, truth_ids: np.ndarray, threshold: float = 0.5
) -> list[tuple[int, bool]]:
    """(area in px, matched with IoU > threshold) of each ground-truth instance, by id."""
    ids = [int(i) for i in np.unique(truth_ids) if i != 0]
    if not ids:
        return []
    areas = [int(np.count_nonzero(truth_ids == instance)) for instance in ids]
    labels, count = ndimage.label(predicted, structure=EIGHT_CONNECTED)
    if count == 0:
        return [(area, False) for area in areas]
    ious = np.zeros((len(ids), count))
    component_areas = np.bincount(labels.ravel(), minlength=count + 1)[1:]
    for row, instance in enumerate(ids):
        inside = truth_ids == instance
        shared = np.bincount(labels[inside], minlength=count + 1)[1:]
        ious[row] = shared / (areas[row] + component_areas - shared)
    found = [False] * len(ids)
    rows, cols = linear_sum_assignment(ious, maximize=True)
    for row, col in zip(rows, cols):
        found[row] = bool(ious[row, col] > threshold)
    return list(zip(areas, found))


@dataclass
class SequenceScores:
    """Per-frame scores of one sequence, averaged per sequence (then over sequences)."""

    frames: list[FrameScores] = field(default_factory=list)

    def add(self, scores: FrameScores) -> None:
        self.frames.append(scores)

    def summary(self) -> dict[str, float]:
        def mean(name: str) -> float:
            values = np.array([getattr(f, name) for f in self.frames], dtype=float)
            return float(np.nanmean(values)) if np.isfinite(values).any() else float("nan")

        truth_px = sum(f.truth_px for f in self.frames)

        def share_of_truth(name: str) -> float:
            return sum(getattr(f, name) for f in self.frames) / truth_px if truth_px else float("nan")

        def recall_of_band(smallest: int, above: int | None) -> float:
            flags = [
                found
                for f in self.frames
                for area, found in f.instances
                if area >= smallest and (above is None or area < above)
            ]
            return float(np.mean(flags)) if flags else float("nan")

        return {
            "frames": len(self.frames),
            "miou": mean("miou"),
            "imo_iou": mean("imo_iou"),
            "piou": mean("piou"),
            "sr50": float(np.mean([f.success for f in self.frames])) if self.frames else float("nan"),
            "r50": recall_of_band(0, None),
            **{f"r50_{name}": recall_of_band(smallest, above) for name, smallest, above in INSTANCE_AREA_BANDS},
            "area_ratio": share_of_truth("predicted_px"),
            "false_negative_share": share_of_truth("false_negative_px"),
            "false_positive_share": share_of_truth("false_positive_px"),
            "false_positive_far_share": share_of_truth("false_positive_far_px"),
        }
