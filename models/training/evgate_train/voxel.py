"""The voxel grid; at the default 2 bins identical to evgate-core's
(crates/evgate-core/src/voxel.rs).

For a window [t_end - 50 ms, t_end] (both ends included, as evgate-core's `accumulate`, so
the event at the reference time counts) each event at (x, y, t) with polarity p adds
s = +1 (ON) or -1 (OFF) to the two bins around its normalised time tau = (t - t_start) / 50 ms
in [0, 1], with bin b centred at tau = b / (B - 1) and linear (triangular) weights; at B = 2:

    V[0, y, x] += s * (1 - tau)        V[1, y, x] += s * tau

Then the non-zero cells are standardised over the whole padded grid: with mean m and sample
standard deviation d (n - 1 denominator, E-RAFT's `torch.std`; 0 for fewer than two cells) of
the non-zero cells, each non-zero cell becomes (v - m) / d (or v - m when d = 0); zero cells
stay zero. The grid is the sensor padded with
zeros at the right and bottom to multiples of 16.
"""

import numpy as np

WINDOW_US = 50_000
BINS = 2
PAD_MULTIPLE = 16


class EventOutOfSensorError(ValueError):
    """An event whose pixel lies outside the sensor."""


def padded(length: int) -> int:
    return -(-length // PAD_MULTIPLE) * PAD_MULTIPLE


class BinCountError(ValueError):
    """A voxel grid of fewer than two bins."""


def accumulate(
    t: np.ndarray, x: np.ndarray, y: np.ndarray, on: np.ndarray, t_end: int, width: int, height: int, bins: int = BINS
) -> np.ndarray:
    """Raw (unnormalised) voxel grid [bins, padded(height), padded(width)], float32, of the
    events of [t_end - 50 ms, t_end]; events outside that window are ignored."""
    if bins < 2:
        raise BinCountError(f"voxel bins {bins}: accepted 2 or more")
    t_start = t_end - WINDOW_US
    inside = (t >= t_start) & (t <= t_end)
    t, x, y, on = t[inside], x[inside].astype(np.int64), y[inside].astype(np.int64), on[inside]
    if x.size and (x.max() >= width or y.max() >= height):
        bad = int(np.flatnonzero((x >= width) | (y >= height))[0])
        raise EventOutOfSensorError(
            f"event at x = {x[bad]}, y = {y[bad]} lies outside the {width}x{height} sensor"
        )
    grid_h, grid_w = padded(height), padded(width)
    position = (t - t_start).astype(np.float64) / WINDOW_US * (bins - 1)
    # The last event (tau = 1) falls wholly into the last bin, not one beyond it.
    lower = np.minimum(np.floor(position).astype(np.int64), bins - 2)
    upper_weight = position - lower
    sign = np.where(on.astype(bool), 1.0, -1.0)
    pixel = y * grid_w + x
    cells = grid_h * grid_w
    grid = np.bincount(lower * cells + pixel, weights=sign * (1.0 - upper_weight), minlength=bins * cells)
    grid += np.bincount((lower + 1) * cells + pixel, weights=sign * upper_weight, minlength=bins * cells)
    return grid.reshape(bins, grid_h, grid_w).astype(np.float32)


def normalise(grid: np.ndarray) -> np.ndarray:
    """Standardises the non-zero cells (mean / sample std), in place and returned."""
    nonzero = grid != 0
    if not nonzero.any():
        return grid
    values = grid[nonzero].astype(np.float64)
    mean = values.mean()
    std = values.std(ddof=1) if values.size > 1 else 0.0
    grid[nonzero] = ((values - mean) / std if std > 0 else values - mean).astype(np.float32)
    return grid


def voxel_grid(
    t: np.ndarray, x: np.ndarray, y: np.ndarray, on: np.ndarray, t_end: int, width: int, height: int, bins: int = BINS
) -> np.ndarray:
    return normalise(accumulate(t, x, y, on, t_end, width, height, bins))
