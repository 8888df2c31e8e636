"""A tiny labelled sequence for the tests: a textured square sliding right over a static,
textured background, events from frame-to-frame brightness changes every millisecond. Written
in the docs/sequence-format.md layout so the product's reader is exercised as is."""

import json
from pathlib import Path

import numpy as np

WIDTH, HEIGHT = 96, 48
DURATION_MS = 400
SPEED_PX_PER_MS = 0.15
SIDE = 14
START_X, START_Y = 8.0, 17.0


def _texture(rng: np.random.Generator, height: int, width: int) -> np.ndarray:
    coarse = rng.random((height // 4 + 2, width // 4 + 2))
    return np.kron(coarse, np.ones((4, 4)))[:height, :width]


def square_left(time_ms: float) -> float:
    return START_X + SPEED_PX_PER_MS * time_ms


def object_mask(time_ms: float) -> np.ndarray:
    mask = np.zeros((HEIGHT, WIDTH), np.uint8)
    left = int(round(square_left(time_ms)))
    top = int(START_Y)
    mask[top : top + SIDE, max(left, 0) : min(left + SIDE, WIDTH)] = 1
    return mask


def render(time_ms: float, background: np.ndarray, pattern: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    image = background.copy()
    mask = object_mask(time_ms)
    left = int(round(square_left(time_ms)))
    top = int(START_Y)
    for row in range(SIDE):
        for col in range(SIDE):
            x = left + col
            if 0 <= x < WIDTH:
                image[top + row, x] = pattern[row, col]
    return image, mask


def events(seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t µs, x, y, on) of the whole sequence, time-sorted."""
    rng = np.random.default_rng(seed)
    background = 0.2 + 0.3 * _texture(rng, HEIGHT, WIDTH)
    pattern = 0.5 + 0.5 * _texture(rng, SIDE, SIDE)
    log_previous = np.log(render(0, background, pattern)[0])
    ts, xs, ys, ps = [], [], [], []
    for ms in range(1, DURATION_MS + 1):
        log_now = np.log(render(ms, background, pattern)[0])
        change = log_now - log_previous
        rows, cols = np.nonzero(np.abs(change) > 0.15)
        ts.append(np.full(rows.size, ms * 1000 - 500 + rng.integers(0, 500, rows.size), np.int64))
        xs.append(cols)
        ys.append(rows)
        ps.append((change[rows, cols] > 0).astype(np.uint8))
        log_previous[rows, cols] = log_now[rows, cols]
    t = np.concatenate(ts)
    order = np.argsort(t, kind="stable")
    return t[order], np.concatenate(xs)[order], np.concatenate(ys)[order], np.concatenate(ps)[order]


def labels(t: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """1 for the events the square fires (its pixels in the frame before or after the change)."""
    out = np.zeros(t.size, np.uint16)
    ms = (t + 999) // 1000
    for step in np.unique(ms):
        at = ms == step
        on_square = (object_mask(step)[y[at], x[at]] | object_mask(step - 1)[y[at], x[at]]) > 0
        out[np.flatnonzero(at)[on_square]] = 1
    return out


def write_sequence(path: Path, seed: int = 0, horizons_per_reference: int = 2) -> Path:
    rng = np.random.default_rng(seed + 1)
    t, x, y, on = events(seed)
    gt_ts = np.arange(0, DURATION_MS * 1000 + 1, 10_000, dtype=np.int64)
    masks = np.stack([object_mask(ts / 1000) for ts in gt_ts])
    ref_ts = np.arange(50_000, (DURATION_MS - 100) * 1000 + 1, 50_000, dtype=np.int64)
    horizon_us = rng.integers(0, 100_001, (len(ref_ts), horizons_per_reference)).astype(np.int64)
    future_mask = np.zeros((len(ref_ts), horizons_per_reference, HEIGHT, WIDTH), np.uint8)
    future_flow = np.zeros((len(ref_ts), horizons_per_reference, HEIGHT, WIDTH, 2), np.float16)
    for r, ref in enumerate(ref_ts):
        for k, horizon in enumerate(horizon_us[r]):
            future_mask[r, k] = object_mask((ref + horizon) / 1000)
            future_flow[r, k, object_mask(ref / 1000) > 0, 0] = SPEED_PX_PER_MS * horizon / 1000
    meta = json.dumps({"preset": "synthetic-test", "seed": seed}).encode()
    np.savez(
        path,
        events_t=t,
        events_xy=np.stack([x, y], axis=1).astype(np.uint16),
        events_p=on,
        events_label=labels(t, x, y),
        resolution=np.array([WIDTH, HEIGHT], np.int64),
        K=np.eye(3),
        gt_ts=gt_ts,
        mask=masks,
        depth=np.ones((len(gt_ts), HEIGHT, WIDTH), np.float16),
        ref_ts=ref_ts,
        horizon_us=horizon_us,
        future_mask=future_mask,
        future_flow=future_flow,
        meta=np.frombuffer(meta, np.uint8),
    )
    return path
