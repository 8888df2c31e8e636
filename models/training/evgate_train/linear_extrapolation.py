"""The linear-extrapolation baseline (as evgate-eval's): every connected component of the
current mask moves on at its centroid's velocity between the previous window's mask and the
current one; components are paired by the Hungarian algorithm on centroid distance, and pairs
farther apart than a limit, or unpaired components, keep still."""

import numpy as np
from scipy import ndimage
from scipy.optimize import linear_sum_assignment

from .metrics import EIGHT_CONNECTED

MAX_MATCH_DISTANCE_PX = 40.0


def _components(mask: np.ndarray) -> tuple[np.ndarray, int, np.ndarray]:
    labels, count = ndimage.label(mask, structure=EIGHT_CONNECTED)
    centroids = np.array(ndimage.center_of_mass(mask, labels, range(1, count + 1))).reshape(count, 2)
    return labels, count, centroids  # centroids as (row, col)


def extrapolate(previous: np.ndarray, current: np.ndarray, elapsed_ms: float, horizon_ms: float) -> np.ndarray:
    """Forecast of the bool mask `current` at `horizon_ms`, given the mask `elapsed_ms` earlier."""
    labels, count, centroids = _components(current)
    _, previous_count, previous_centroids = _components(previous)
    forecast = np.zeros_like(current, dtype=bool)
    velocities = np.zeros((count, 2))
    if count and previous_count and elapsed_ms > 0:
        distance = np.linalg.norm(centroids[:, None, :] - previous_centroids[None, :, :], axis=-1)
        rows, cols = linear_sum_assignment(distance)
        for now, before in zip(rows, cols):
            if distance[now, before] <= MAX_MATCH_DISTANCE_PX:
                velocities[now] = (centroids[now] - previous_centroids[before]) / elapsed_ms
    for index in range(count):
        row_shift, col_shift = np.round(velocities[index] * horizon_ms).astype(int)
        rows, cols = np.nonzero(labels == index + 1)
        mark_inside(forecast, rows + row_shift, cols + col_shift)
    return forecast


def mark_inside(mask: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> None:
    """Sets the pixels (rows, cols) of `mask` that lie inside it; moved pixels may leave the image."""
    height, width = mask.shape
    inside = (rows >= 0) & (rows < height) & (cols >= 0) & (cols < width)
    mask[rows[inside], cols[inside]] = True
