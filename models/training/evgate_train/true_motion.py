"""Oracle forecasts for diagnosis (`evaluate`): the model's current mask with each 8-connected
component moved by the true motion of the object it covers. They use ground truth no runtime
has, so they bound what a better flow would give the model's own current mask, and so split the
forecast's loss into the mask's share and the flow's.

- true-motion-<h>ms: the shift of the object's centroid between the true masks at t and t + h,
  which no forecast made at t can know. A component whose object has left the frame by t + h
  is dropped.
- true-kinematics-<h>ms: the object's true past only, the parabola through its centroids at
  t - 2s, t - s and t (s = `KINEMATICS_STEP_MS`) carried on to t + h: what a flow that read each
  object's velocity and acceleration perfectly from the history could do. A component whose
  object is missing at one of those times keeps still.

A component belongs to the true object with the most of its pixels within `REACH_PX` of that
object at t (the higher id where two are that near); one near no object keeps still (a false
positive stays one).
"""

from collections.abc import Callable

import numpy as np
from scipy import ndimage

from .linear_extrapolation import mark_inside
from .metrics import EIGHT_CONNECTED
from .sequence import Sequence

REACH_PX = 5
# On full val with S, 20 ms scored above 50 ms (mIoU at t + 100 ms +1.4 against +0.8 over S's
# forecast), and the constant velocity of the last 10, 20 or 50 ms below both.
KINEMATICS_STEP_MS = 20.0

STILL = (0.0, 0.0)
# (row, col) shift of the components an object id owns, or None to drop them.
Shift = tuple[float, float] | None


def true_motion_forecast(current: np.ndarray, truth_now: np.ndarray, truth_future: np.ndarray) -> np.ndarray:
    """current: bool [H, W]; truth_now, truth_future: object ids [H, W] (0 = background)."""

    def shift(owner: int) -> Shift:
        now, future = _centroid(truth_now, owner), _centroid(truth_future, owner)
        return None if future is None else (future[0] - now[0], future[1] - now[1])

    return _moved_per_object(current, truth_now, shift)


def true_kinematics_forecast(
    current: np.ndarray, truth_past: tuple[np.ndarray, np.ndarray, np.ndarray], horizon_ms: float
) -> np.ndarray:
    """current: bool [H, W]; truth_past: object ids [H, W] at t - 2s, t - s and t
    (s = `KINEMATICS_STEP_MS`)."""
    earliest, earlier, now = truth_past
    steps = horizon_ms / KINEMATICS_STEP_MS

    def shift(owner: int) -> Shift:
        points = [_centroid(ids, owner) for ids in (earliest, earlier, now)]
        if any(point is None for point in points):
            return STILL
        c2, c1, c0 = (np.array(point) for point in points)
        # p(k) through (-2, c2), (-1, c1), (0, c0), evaluated at k = steps, less p(0).
        moved = steps * (3 * c0 - 4 * c1 + c2) / 2 + steps * steps * (c0 - 2 * c1 + c2) / 2
        return float(moved[0]), float(moved[1])

    return _moved_per_object(current, now, shift)


def true_history(sequence: Sequence, t_end: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The true object ids at t - 2s, t - s and t (s = `KINEMATICS_STEP_MS`) that
    `true_kinematics_forecast` reads, or None where the ground-truth grid lacks one of them."""
    frames = [sequence.grid_index(t_end - round(k * KINEMATICS_STEP_MS * 1000)) for k in (2, 1, 0)]
    if None in frames:
        return None
    return tuple(sequence.masks[frame] for frame in frames)


def _centroid(ids: np.ndarray, owner: int) -> tuple[float, float] | None:
    rows, cols = np.nonzero(ids == owner)
    return (float(rows.mean()), float(cols.mean())) if rows.size else None


def _moved_per_object(current: np.ndarray, truth_now: np.ndarray, shift_of: Callable[[int], Shift]) -> np.ndarray:
    near = ndimage.grey_dilation(truth_now, size=(2 * REACH_PX + 1, 2 * REACH_PX + 1))
    labels, count = ndimage.label(current, structure=EIGHT_CONNECTED)
    forecast = np.zeros_like(current, dtype=bool)
    for component in range(1, count + 1):
        rows, cols = np.nonzero(labels == component)
        owners = near[rows, cols]
        owners = owners[owners > 0]
        shift = shift_of(int(np.bincount(owners).argmax())) if owners.size else STILL
        if shift is None:
            continue
        mark_inside(forecast, rows + int(round(shift[0])), cols + int(round(shift[1])))
    return forecast
