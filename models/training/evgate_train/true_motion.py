"""An oracle forecast for diagnosis (`evaluate`, key true-motion-<h>ms): the model's current mask
with each 8-connected component moved by the true displacement of the object it covers, the
shift of that object's centroid between the true masks at t and t + h. It uses the future
ground truth, so no runtime can make it: it bounds what a perfect per-object motion would give
the model's own current mask, and so splits the forecast's loss into the mask's share and the
flow's.

A component belongs to the true object with the most of its pixels within `REACH_PX` of that
object at t (the higher id where two are that near); one near no object keeps still (a false
positive stays one), and one whose object has left the frame by t + h is dropped.
"""

import numpy as np
from scipy import ndimage

from .linear_extrapolation import mark_inside
from .metrics import EIGHT_CONNECTED

REACH_PX = 5


def true_motion_forecast(current: np.ndarray, truth_now: np.ndarray, truth_future: np.ndarray) -> np.ndarray:
    """current: bool [H, W]; truth_now, truth_future: object ids [H, W] (0 = background)."""
    near = ndimage.grey_dilation(truth_now, size=(2 * REACH_PX + 1, 2 * REACH_PX + 1))
    labels, count = ndimage.label(current, structure=EIGHT_CONNECTED)
    forecast = np.zeros_like(current, dtype=bool)
    for component in range(1, count + 1):
        rows, cols = np.nonzero(labels == component)
        owners = near[rows, cols]
        owners = owners[owners > 0]
        if owners.size == 0:
            mark_inside(forecast, rows, cols)
            continue
        owner = np.bincount(owners).argmax()
        future_rows, future_cols = np.nonzero(truth_future == owner)
        if future_rows.size == 0:
            continue
        now_rows, now_cols = np.nonzero(truth_now == owner)
        row_shift = int(round(future_rows.mean() - now_rows.mean()))
        col_shift = int(round(future_cols.mean() - now_cols.mean()))
        mark_inside(forecast, rows + row_shift, cols + col_shift)
    return forecast
