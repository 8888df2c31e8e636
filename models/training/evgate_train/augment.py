"""Flips and polarity inversion, applied alike to the voxel grid, masks, flow and events.

One draw per training chunk: the recurrence must see one consistent world across windows.
"""

from dataclasses import dataclass

import numpy as np

from .windows import FutureEvents, TrainingWindow


@dataclass(frozen=True)
class Augmentation:
    flip_horizontal: bool
    flip_vertical: bool
    invert_polarity: bool

    @staticmethod
    def draw(rng: np.random.Generator) -> "Augmentation":
        return Augmentation(bool(rng.random() < 0.5), bool(rng.random() < 0.5), bool(rng.random() < 0.5))


def apply(window: TrainingWindow, augmentation: Augmentation, size: int) -> TrainingWindow:
    voxel, mask, future_mask = window.voxel, window.mask, window.future_mask
    flow, flow_valid = window.future_flow.copy(), window.flow_valid
    events = list(window.future_events)
    if augmentation.flip_horizontal:
        voxel, mask, future_mask = voxel[..., ::-1], mask[..., ::-1], future_mask[..., ::-1]
        flow, flow_valid = flow[..., ::-1], flow_valid[..., ::-1]
        flow[:, 0] = -flow[:, 0]
        events = [FutureEvents(size - 1 - e.x, e.y, e.t_ms, e.on) for e in events]
    if augmentation.flip_vertical:
        voxel, mask, future_mask = voxel[..., ::-1, :], mask[..., ::-1, :], future_mask[..., ::-1, :]
        flow, flow_valid = flow[..., ::-1, :], flow_valid[..., ::-1, :]
        flow[:, 1] = -flow[:, 1]
        events = [FutureEvents(e.x, size - 1 - e.y, e.t_ms, e.on) for e in events]
    if augmentation.invert_polarity:
        # Negating every event's sign negates the raw grid, its non-zero mean, and so the
        # standardised grid: the voxel of the inverted stream is exactly -voxel.
        voxel = -voxel
        events = [FutureEvents(e.x, e.y, e.t_ms, ~e.on) for e in events]
    return TrainingWindow(
        voxel=np.ascontiguousarray(voxel),
        mask=np.ascontiguousarray(mask),
        mask_valid=window.mask_valid,
        horizons_ms=window.horizons_ms,
        future_mask=np.ascontiguousarray(future_mask),
        future_flow=np.ascontiguousarray(flow),
        flow_valid=np.ascontiguousarray(flow_valid),
        future_events=events,
    )
