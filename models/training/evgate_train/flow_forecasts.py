"""Forecasts made from a network's current mask and its flow without backward warping, for
diagnosis (`evaluate --flow-variants`): does the learned forecast lose to linear extrapolation
because of how the mask is warped, or because of the flow itself?

- rigid: every 8-connected component of the current mask moves by the median of the flow over
  its own pixels (one translation per object, as linear extrapolation moves it, but with the
  learned flow instead of the centroids' velocity);
- splat: every mask pixel moves by its own flow (forward splatting, nearest pixel), then a 3x3
  closing fills the one-pixel holes that rounding leaves.

Neither fills the strip an object uncovers, which backward warping does unless the flow there
points past the object.
"""

import numpy as np
from scipy import ndimage

from .linear_extrapolation import mark_inside
from .metrics import EIGHT_CONNECTED

CLOSING = np.ones((3, 3), dtype=bool)


def rigid_forecast(current: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """current: bool [H, W]; flow: (dx, dy) [2, H, W] in pixels over the horizon."""
    labels, count = ndimage.label(current, structure=EIGHT_CONNECTED)
    forecast = np.zeros_like(current, dtype=bool)
    for component in range(1, count + 1):
        rows, cols = np.nonzero(labels == component)
        dx = int(round(float(np.median(flow[0][rows, cols]))))
        dy = int(round(float(np.median(flow[1][rows, cols]))))
        mark_inside(forecast, rows + dy, cols + dx)
    return forecast


def splat_forecast(current: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """current: bool [H, W]; flow: (dx, dy) [2, H, W] in pixels over the horizon."""
    rows, cols = np.nonzero(current)
    moved = np.zeros_like(current, dtype=bool)
    mark_inside(moved, np.round(rows + flow[1][rows, cols]).astype(int), np.round(cols + flow[0][rows, cols]).astype(int))
    return ndimage.binary_closing(moved, structure=CLOSING)
