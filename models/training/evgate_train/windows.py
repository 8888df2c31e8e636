"""Training windows: one 50 ms window of a sequence, cropped, with its targets."""

from dataclasses import dataclass

import numpy as np

from .sequence import Sequence
from .voxel import WINDOW_US, voxel_grid


@dataclass
class Crop:
    left: int
    top: int
    size: int


@dataclass
class FutureEvents:
    """Events of [t, t + h) inside the crop: crop pixel coordinates, ms since t, polarity."""

    x: np.ndarray
    y: np.ndarray
    t_ms: np.ndarray
    on: np.ndarray


@dataclass
class TrainingWindow:
    voxel: np.ndarray  # [2, S, S] float32
    mask: np.ndarray  # [S, S] float32, 1 = IMO
    mask_valid: bool  # the reference time has a ground-truth frame
    horizons_ms: np.ndarray  # [K] float32
    future_mask: np.ndarray  # [K, S, S] float32
    future_flow: np.ndarray  # [K, 2, S, S] float32, pixels
    flow_valid: np.ndarray  # [K, S, S] bool
    future_events: list[FutureEvents]  # K entries


def reference_voxel(sequence: Sequence, reference: int) -> np.ndarray:
    """The full-frame voxel grid [2, H, W] of the 50 ms window ending at reference time `reference`."""
    t_end = int(sequence.ref_ts[reference])
    window = sequence.event_range(t_end - WINDOW_US, t_end + 1)
    return voxel_grid(
        sequence.events_t[window],
        sequence.events_x[window],
        sequence.events_y[window],
        sequence.events_on[window],
        t_end,
        sequence.width,
        sequence.height,
    )


def arrival_flow(
    sequence: Sequence, reference: int, grid_index: int | None, rows: slice, cols: slice, flow: np.ndarray,
    flow_valid: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Backward warping reads the flow at the pixel an object reaches, but the simulator's flow
    is defined at the pixel it leaves: ahead of a moving object it is the background's. Inside
    each object's footprint at t + h this returns the object's mean flow at t (a rigid
    translation); elsewhere, and without a mask at t, the simulator's flow."""
    if grid_index is None:
        return flow, flow_valid
    ids_now = sequence.masks[grid_index]
    future_ids = sequence.future_mask[reference, :, rows, cols]
    flow, flow_valid = flow.copy(), flow_valid.copy()
    for k in range(future_ids.shape[0]):
        for object_id in np.unique(future_ids[k]):
            if object_id == 0:
                continue
            vectors = sequence.future_flow[reference, k][ids_now == object_id].astype(np.float32)
            vectors = vectors[np.isfinite(vectors).all(axis=1)]
            if len(vectors) == 0:
                continue
            target = future_ids[k] == object_id
            flow[k][:, target] = vectors.mean(axis=0)[:, None]
            flow_valid[k][target] = True
    return flow, flow_valid


def training_window(
    sequence: Sequence,
    reference: int,
    crop: Crop,
    max_events: int,
    rng: np.random.Generator,
    full: np.ndarray,
    flow_at_arrival: bool = False,
) -> TrainingWindow:
    """`full` is `reference_voxel(sequence, reference)`, passed in so callers can cache it;
    `flow_at_arrival` replaces the flow target inside objects' future footprints (`arrival_flow`)."""
    t_end = int(sequence.ref_ts[reference])
    rows = slice(crop.top, crop.top + crop.size)
    cols = slice(crop.left, crop.left + crop.size)
    grid_index = sequence.grid_index(t_end)
    mask = (
        (sequence.masks[grid_index, rows, cols] > 0).astype(np.float32)
        if grid_index is not None
        else np.zeros((crop.size, crop.size), np.float32)
    )
    horizons_us = sequence.horizon_us[reference]
    flow = sequence.future_flow[reference, :, rows, cols, :].astype(np.float32).transpose(0, 3, 1, 2)
    flow_valid = np.isfinite(flow).all(axis=1)
    if flow_at_arrival:
        flow, flow_valid = arrival_flow(sequence, reference, grid_index, rows, cols, flow, flow_valid)
    events = []
    for horizon in horizons_us:
        future = sequence.event_range(t_end, t_end + int(horizon))
        x = sequence.events_x[future].astype(np.int64) - crop.left
        y = sequence.events_y[future].astype(np.int64) - crop.top
        inside = np.flatnonzero((x >= 0) & (x < crop.size) & (y >= 0) & (y < crop.size))
        if inside.size > max_events:
            inside = np.sort(rng.choice(inside, max_events, replace=False))
        t_ms = (sequence.events_t[future][inside] - t_end).astype(np.float32) / 1000.0
        events.append(
            FutureEvents(
                x=x[inside].astype(np.float32),
                y=y[inside].astype(np.float32),
                t_ms=t_ms,
                on=sequence.events_on[future][inside],
            )
        )
    return TrainingWindow(
        voxel=np.ascontiguousarray(full[:, rows, cols]),
        mask=mask,
        mask_valid=grid_index is not None,
        horizons_ms=(horizons_us / 1000.0).astype(np.float32),
        future_mask=(sequence.future_mask[reference, :, rows, cols] > 0).astype(np.float32),
        future_flow=np.where(np.isfinite(flow), flow, 0.0).astype(np.float32),
        flow_valid=flow_valid,
        future_events=events,
    )
