"""Flips and polarity inversion, applied alike to the voxel grid, targets and events, and the
event jitter that only the voxel grid sees (built with it, `reference_input`).

One draw per stream: the recurrence must see one consistent world across windows.
"""

import dataclasses
from dataclasses import dataclass

import numpy as np

from .jitter import EventJitter
from .voxel import BINS
from .windows import FutureEvents, TrainingWindow

# [..., H, W] fields of a TrainingWindow that flip with the image.
SPATIAL_FIELDS = (
    "voxel",
    "mask",
    "fired",
    "future_mask",
    "future_fired",
    "footprint",
    "future_flow",
    "flow_valid",
    "object_region",
)


@dataclass(frozen=True)
class Augmentation:
    flip_horizontal: bool
    flip_vertical: bool
    invert_polarity: bool
    jitter: EventJitter = EventJitter()

    @staticmethod
    def draw(rng: np.random.Generator) -> "Augmentation":
        return Augmentation(bool(rng.random() < 0.5), bool(rng.random() < 0.5), bool(rng.random() < 0.5))

    @staticmethod
    def none() -> "Augmentation":
        return Augmentation(False, False, False)

    @staticmethod
    def from_dict(fields: dict) -> "Augmentation":
        """The inverse of `dataclasses.asdict`; a cursor saved before jitter existed has none."""
        fields = dict(fields)
        jitter = EventJitter(**fields.pop("jitter", {}))
        return Augmentation(**fields, jitter=jitter)


def inverted_polarity(voxel: np.ndarray, voxel_bins: int) -> np.ndarray:
    """The network input of the polarity-inverted stream: negating every event's sign negates
    the raw grid, its non-zero mean, and so the standardised grid, exactly; channels after the
    voxel bins count events regardless of polarity and stay."""
    inverted = voxel.copy()
    inverted[:voxel_bins] *= -1
    return inverted


def augmented_voxel(voxel: np.ndarray, augmentation: Augmentation, voxel_bins: int = BINS) -> np.ndarray:
    """The network input [C, H, W] as `apply` augments it (rebuilding a stream's recurrent
    state)."""
    if augmentation.flip_horizontal:
        voxel = voxel[..., ::-1]
    if augmentation.flip_vertical:
        voxel = voxel[..., ::-1, :]
    return np.ascontiguousarray(inverted_polarity(voxel, voxel_bins) if augmentation.invert_polarity else voxel)


def apply(window: TrainingWindow, augmentation: Augmentation, voxel_bins: int = BINS) -> TrainingWindow:
    fields = {name: getattr(window, name) for name in SPATIAL_FIELDS}
    height, width = window.mask.shape
    events = list(window.future_events)
    if augmentation.flip_horizontal:
        fields = {name: value[..., ::-1] for name, value in fields.items()}
        fields["future_flow"] = fields["future_flow"] * np.array([-1, 1], np.float32)[:, None, None]
        events = [FutureEvents(width - 1 - e.x, e.y, e.t_ms, e.on) for e in events]
    if augmentation.flip_vertical:
        fields = {name: value[..., ::-1, :] for name, value in fields.items()}
        fields["future_flow"] = fields["future_flow"] * np.array([1, -1], np.float32)[:, None, None]
        events = [FutureEvents(e.x, height - 1 - e.y, e.t_ms, e.on) for e in events]
    if augmentation.invert_polarity:
        fields["voxel"] = inverted_polarity(fields["voxel"], voxel_bins)
        events = [FutureEvents(e.x, e.y, e.t_ms, ~e.on) for e in events]
    return dataclasses.replace(
        window, **{name: np.ascontiguousarray(value) for name, value in fields.items()}, future_events=events
    )
