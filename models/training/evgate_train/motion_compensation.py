"""The ego-motion-compensated input channel: the image of a window's events warped to the
window's end by the one global velocity that makes that image sharpest (contrast
maximisation, Gallego et al., CVPR 2018).

The camera's motion sweeps every static edge across the sensor; warped back by the fitted
velocity, the events of those edges fold into thin, dense lines. An independently moving
object's events move otherwise, so they stay smeared. The channel gives the network that motion
inconsistency directly instead of leaving it to infer it from the look of the scene.

For a window [t_end - 50 ms, t_end] each event at pixel (x, y) and time t lands at
p = (x + 0.5 + vx * dt, y + 0.5 + vy * dt) with dt = (t_end - t) in seconds, and counts in the
pixel floor(p) when p lies inside the sensor. The velocity v (px/s) maximises the sum of squared
counts, searched coarse to fine on `SEARCH_LEVELS` over an evenly strided subset of at most
`MAX_FIT_EVENTS` events; the first candidate wins ties (x outer, y inner, each ascending).
Windows with fewer than `MIN_FIT_EVENTS` events keep v = 0. The image of every event of the
window at the fitted v is then divided by the mean of its non-zero pixels, so its scale does
not depend on the event rate; the grid is padded with zeros like the voxel grid.
"""

import numpy as np

from .voxel import WINDOW_US, padded

MAX_FIT_EVENTS = 4096
MIN_FIT_EVENTS = 64
# (cell size in px, velocity step in px/s, steps on each side of the previous level's best).
# The first level spans +-960 px/s: 48 px over the window, 3.8 rad/s at the simulator's 250 px
# focal length. Each later level halves the cell and the step around the best so far.
SEARCH_LEVELS = ((8, 160.0, 6), (4, 80.0, 2), (2, 40.0, 2), (1, 20.0, 2))


def _window_events(t: np.ndarray, x: np.ndarray, y: np.ndarray, t_end: int):
    inside = (t >= t_end - WINDOW_US) & (t <= t_end)
    seconds = (t_end - t[inside]).astype(np.float64) / 1e6
    return seconds, x[inside].astype(np.float64) + 0.5, y[inside].astype(np.float64) + 0.5


def _sharpness(
    dt: np.ndarray, px: np.ndarray, py: np.ndarray, candidates: np.ndarray, cell: int, width: int, height: int
) -> np.ndarray:
    """The sum of squared counts of the warped-event image on `cell`-pixel cells, per candidate
    velocity ([C, 2] px/s)."""
    wx = px[None, :] + candidates[:, :1] * dt[None, :]
    wy = py[None, :] + candidates[:, 1:] * dt[None, :]
    inside = (wx >= 0) & (wx < width) & (wy >= 0) & (wy < height)
    cells_x, cells_y = -(-width // cell), -(-height // cell)
    cx = np.floor(wx / cell).astype(np.int64)
    cy = np.floor(wy / cell).astype(np.int64)
    flat = (np.arange(len(candidates))[:, None] * (cells_y * cells_x) + cy * cells_x + cx)[inside]
    counts = np.bincount(flat, minlength=len(candidates) * cells_y * cells_x).astype(np.int64)
    return (counts * counts).reshape(len(candidates), -1).sum(axis=1)


def fit_velocity(t: np.ndarray, x: np.ndarray, y: np.ndarray, t_end: int, width: int, height: int) -> np.ndarray:
    """The global velocity (vx, vy) in px/s that sharpens the window's events most."""
    return _fitted(*_window_events(t, x, y, t_end), width, height)


def _fitted(dt: np.ndarray, px: np.ndarray, py: np.ndarray, width: int, height: int) -> np.ndarray:
    best = np.zeros(2)
    if len(dt) < MIN_FIT_EVENTS:
        return best
    stride = -(-len(dt) // MAX_FIT_EVENTS)
    dt, px, py = dt[::stride], px[::stride], py[::stride]
    for cell, step, reach in SEARCH_LEVELS:
        offsets = np.arange(-reach, reach + 1) * step
        candidates = np.stack(np.meshgrid(best[0] + offsets, best[1] + offsets, indexing="ij"), -1).reshape(-1, 2)
        best = candidates[int(np.argmax(_sharpness(dt, px, py, candidates, cell, width, height)))]
    return best


def compensated_image(
    t: np.ndarray, x: np.ndarray, y: np.ndarray, t_end: int, width: int, height: int
) -> np.ndarray:
    """The channel [1, padded(height), padded(width)] float32 of the events of
    [t_end - 50 ms, t_end] (see the module's docstring)."""
    dt, px, py = _window_events(t, x, y, t_end)
    velocity = _fitted(dt, px, py, width, height)
    wx, wy = px + velocity[0] * dt, py + velocity[1] * dt
    inside = (wx >= 0) & (wx < width) & (wy >= 0) & (wy < height)
    grid_h, grid_w = padded(height), padded(width)
    flat = np.floor(wy[inside]).astype(np.int64) * grid_w + np.floor(wx[inside]).astype(np.int64)
    counts = np.bincount(flat, minlength=grid_h * grid_w).astype(np.float64)
    nonzero = counts > 0
    if nonzero.any():
        counts /= counts[nonzero].mean()
    return counts.reshape(1, grid_h, grid_w).astype(np.float32)
