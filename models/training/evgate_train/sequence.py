"""Reads the labelled-sequence `.npz` of docs/sequence-format.md into what training and
evaluation need: events, the masks at each reference time, the sampled horizons with their
masks and flows, and the 10 ms ground-truth grid for fixed-horizon evaluation."""

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

GRID_US = 10_000

# key -> (dtype, number of dimensions)
REQUIRED_ARRAYS = {
    "events_t": (np.int64, 1),
    "events_xy": (np.uint16, 2),
    "events_p": (np.uint8, 1),
    "resolution": (np.int64, 1),
    "gt_ts": (np.int64, 1),
    "mask": (np.uint8, 3),
    "ref_ts": (np.int64, 1),
    "horizon_us": (np.int64, 2),
    "future_mask": (np.uint8, 4),
    "future_flow": (np.float16, 5),
    "meta": (np.uint8, 1),
}


class SequenceFormatError(ValueError):
    """A sequence file that does not follow docs/sequence-format.md."""


@dataclass
class Sequence:
    path: Path
    width: int
    height: int
    events_t: np.ndarray  # int64 µs, non-decreasing
    events_x: np.ndarray  # uint16
    events_y: np.ndarray  # uint16
    events_on: np.ndarray  # bool
    gt_ts: np.ndarray  # int64 µs, the 10 ms grid
    masks: np.ndarray  # uint8 object ids [F, H, W] at gt_ts
    ref_ts: np.ndarray  # int64 µs
    horizon_us: np.ndarray  # int64 [R, K]
    future_mask: np.ndarray  # uint8 object ids [R, K, H, W]
    future_flow: np.ndarray  # float16 [R, K, H, W, 2] (dx, dy) pixels
    meta: dict
    # Object id of each event (0 = background), where the file has them.
    events_label: np.ndarray | None = None

    @property
    def preset(self) -> str:
        return str(self.meta.get("preset", "unknown"))

    def event_range(self, start_us: int, end_us: int) -> slice:
        """Indices of the events in [start_us, end_us)."""
        first, last = np.searchsorted(self.events_t, [start_us, end_us], side="left")
        return slice(int(first), int(last))

    def event_pixels(self, start_us: int, end_us: int) -> np.ndarray:
        """[H, W] bool: the pixels with an event in [start_us, end_us)."""
        span = self.event_range(start_us, end_us)
        pixels = np.zeros((self.height, self.width), dtype=bool)
        pixels[self.events_y[span], self.events_x[span]] = True
        return pixels

    def grid_index(self, time_us: int) -> int | None:
        """Index of the ground-truth frame at exactly `time_us`, if the grid has one."""
        index = int(np.searchsorted(self.gt_ts, time_us))
        if index < len(self.gt_ts) and self.gt_ts[index] == time_us:
            return index
        return None


def _check(path: Path, arrays: dict, key: str) -> np.ndarray:
    dtype, dimensions = REQUIRED_ARRAYS[key]
    if key not in arrays:
        raise SequenceFormatError(f"{path}: missing array {key!r}; required: {', '.join(REQUIRED_ARRAYS)}")
    array = arrays[key]
    if array.dtype != dtype or array.ndim != dimensions:
        raise SequenceFormatError(
            f"{path}: array {key!r} is {array.dtype} with {array.ndim} dimensions, "
            f"expected {np.dtype(dtype)} with {dimensions}"
        )
    return array


def load_sequence(path: Path) -> Sequence:
    try:
        archive = np.load(path, allow_pickle=False)
    except (OSError, ValueError, zipfile.BadZipFile) as error:
        raise SequenceFormatError(f"{path}: not a readable .npz: {error}") from error
    with archive:
        arrays = {key: _check(path, archive, key) for key in REQUIRED_ARRAYS}
        labels = archive["events_label"] if "events_label" in archive else None
    width, height = (int(v) for v in arrays["resolution"])
    events_t, events_xy = arrays["events_t"], arrays["events_xy"]
    count = len(events_t)
    if events_xy.shape != (count, 2) or len(arrays["events_p"]) != count:
        raise SequenceFormatError(
            f"{path}: event arrays disagree: events_t has {count} entries, events_xy shape {events_xy.shape}, "
            f"events_p {len(arrays['events_p'])}"
        )
    if count > 1 and np.any(np.diff(events_t) < 0):
        index = int(np.flatnonzero(np.diff(events_t) < 0)[0]) + 1
        raise SequenceFormatError(f"{path}: events_t decreases at index {index} ({events_t[index]} µs)")
    if count and (int(events_xy[:, 0].max()) >= width or int(events_xy[:, 1].max()) >= height):
        raise SequenceFormatError(f"{path}: an event lies outside the {width}x{height} resolution")
    masks = arrays["mask"]
    if masks.shape[1:] != (height, width) or masks.shape[0] != len(arrays["gt_ts"]):
        raise SequenceFormatError(
            f"{path}: mask shape {masks.shape} does not match gt_ts ({len(arrays['gt_ts'])}) x {height} x {width}"
        )
    references = len(arrays["ref_ts"])
    horizons = arrays["horizon_us"].shape[1] if arrays["horizon_us"].ndim == 2 else 0
    if arrays["horizon_us"].shape[0] != references:
        raise SequenceFormatError(f"{path}: horizon_us has {arrays['horizon_us'].shape[0]} rows, ref_ts {references}")
    if arrays["future_mask"].shape != (references, horizons, height, width):
        raise SequenceFormatError(
            f"{path}: future_mask shape {arrays['future_mask'].shape}, expected {(references, horizons, height, width)}"
        )
    if arrays["future_flow"].shape != (references, horizons, height, width, 2):
        raise SequenceFormatError(
            f"{path}: future_flow shape {arrays['future_flow'].shape}, "
            f"expected {(references, horizons, height, width, 2)}"
        )
    try:
        meta = json.loads(arrays["meta"].tobytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise SequenceFormatError(f"{path}: meta is not UTF-8 JSON: {error}") from error
    return Sequence(
        path=path,
        width=width,
        height=height,
        events_t=events_t,
        events_x=events_xy[:, 0].copy(),
        events_y=events_xy[:, 1].copy(),
        events_on=arrays["events_p"] == 1,
        gt_ts=arrays["gt_ts"],
        masks=masks,
        ref_ts=arrays["ref_ts"],
        horizon_us=arrays["horizon_us"],
        future_mask=arrays["future_mask"],
        future_flow=arrays["future_flow"],
        meta=meta if isinstance(meta, dict) else {"value": meta},
        events_label=labels if labels is not None and len(labels) == count else None,
    )
