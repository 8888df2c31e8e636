"""Training windows: one 50 ms window of a sequence, cropped, with targets at horizons of the
10 ms ground-truth grid (what evaluation scores), not at the sequence's sampled horizons."""

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .jitter import EventJitter
from .sequence import GRID_US, Sequence
from .network import NetworkConfig
from .network_input import network_input
from .voxel import WINDOW_US

# Evaluation and the headline figures score the forecast at t + 100 ms: every reference time
# trains it.
SCORED_HORIZON_MS = 100
GRID_HORIZONS_MS = tuple(range(GRID_US // 1000, SCORED_HORIZON_MS, GRID_US // 1000))
# The object region of the flow loss reaches this far beyond the objects' footprints: the ring
# is where a backward warp decides whether an edge moves or smears.
REGION_DILATION_PX = 3
# A mask's fired pixels are those with an event less than this before or after its time: the
# gate judges an event by the mask of the nearest horizon, half a 10 ms grid step either way.
FIRED_HALF_SPAN_US = GRID_US // 2


class HorizonCountError(ValueError):
    """A horizon count outside what the 10 ms grid below 100 ms can give."""


@dataclass
class Crop:
    """A window of the padded frame; parts beyond the sensor are zero (background)."""

    left: int
    top: int
    height: int
    width: int


@dataclass
class FutureEvents:
    """Events of [t, t + h) inside the crop: crop pixel coordinates, ms since t, polarity."""

    x: np.ndarray
    y: np.ndarray
    t_ms: np.ndarray
    on: np.ndarray


@dataclass
class TrainingWindow:
    voxel: np.ndarray  # [C, H, W] float32, the network input (`network_input`)
    mask: np.ndarray  # [H, W] float32, 1 = IMO
    mask_valid: bool  # the reference time has a ground-truth frame
    fired: np.ndarray  # [H, W] bool: an event within FIRED_HALF_SPAN_US of t
    horizons_ms: np.ndarray  # [K] float32
    future_mask: np.ndarray  # [K, H, W] float32
    future_valid: np.ndarray  # [K] bool: t + h lies on the ground-truth grid
    future_fired: np.ndarray  # [K, H, W] bool: an event within FIRED_HALF_SPAN_US of t + h
    footprint: np.ndarray  # [K, H, W] bool: an object at t or at t + h
    future_flow: np.ndarray  # [K, 2, H, W] float32, pixels
    flow_valid: np.ndarray  # [K, H, W] bool
    object_region: np.ndarray  # [K, H, W] bool: the footprint dilated by REGION_DILATION_PX
    future_events: list[FutureEvents]  # K entries; empty arrays when not drawn


def draw_horizons(rng: np.random.Generator, count: int) -> np.ndarray:
    """`count` distinct horizons in ms: the scored 100 ms and `count - 1` of the grid below it."""
    if not 1 <= count <= len(GRID_HORIZONS_MS) + 1:
        raise HorizonCountError(
            f"horizon count {count}: accepted 1 to {len(GRID_HORIZONS_MS) + 1} (100 ms and the 10 ms grid below it)"
        )
    others = rng.choice(GRID_HORIZONS_MS, count - 1, replace=False) if count > 1 else np.empty(0)
    return np.concatenate([[SCORED_HORIZON_MS], np.sort(others)]).astype(np.float32)


def reference_input(
    sequence: Sequence, reference: int, jitter: EventJitter = EventJitter(), config: NetworkConfig = NetworkConfig()
) -> np.ndarray:
    """The full (padded) network input [C, H, W] (`network_input`) of the 50 ms window ending at
    reference time `reference`, of the events as `jitter` alters them."""
    t_end = int(sequence.ref_ts[reference])
    window = sequence.event_range(t_end - WINDOW_US, t_end + 1)
    t, x, y, on = jitter.events(
        sequence.events_t[window],
        sequence.events_x[window],
        sequence.events_y[window],
        sequence.events_on[window],
        sequence.width,
        sequence.height,
        reference,
    )
    return network_input(t, x, y, on, t_end, sequence.width, sequence.height, config)


def cropped(array: np.ndarray, crop: Crop) -> np.ndarray:
    """array[..., H, W] cut to the crop, zero beyond its last two axes' extent."""
    out = np.zeros((*array.shape[:-2], crop.height, crop.width), array.dtype)
    rows = min(crop.height, array.shape[-2] - crop.top)
    cols = min(crop.width, array.shape[-1] - crop.left)
    if rows > 0 and cols > 0:
        out[..., :rows, :cols] = array[..., crop.top : crop.top + rows, crop.left : crop.left + cols]
    return out


@dataclass(frozen=True)
class ObjectPlace:
    centroid: np.ndarray  # (x, y)
    touches_border: bool
    box: tuple[slice, slice]  # rows, columns of the bounding box


def object_places(ids: np.ndarray) -> dict[int, ObjectPlace]:
    """Centroid of each object id in a full frame of ids, and whether it touches the border (its
    centroid then moves with the clipping, not with the object)."""
    places = {}
    height, width = ids.shape
    for index, found in enumerate(ndimage.find_objects(ids)):
        if found is None:
            continue
        object_id = index + 1
        rows, cols = found
        # Within the bounding box: the same centroid as over the frame, at a fraction of the cost.
        centroid = ndimage.center_of_mass(ids[found] == object_id)
        touches = rows.start == 0 or cols.start == 0 or rows.stop == height or cols.stop == width
        places[object_id] = ObjectPlace(
            np.array([centroid[1] + cols.start, centroid[0] + rows.start], np.float32), touches, found
        )
    return places


def dilated_object(
    ids_now: np.ndarray, ids_future: np.ndarray, now: ObjectPlace, future: ObjectPlace, object_id: int
) -> tuple[tuple[slice, slice], np.ndarray]:
    """(slices, pixels): an object's footprint at both times dilated by REGION_DILATION_PX,
    computed inside the union of its two bounding boxes grown by the dilation (it cannot reach
    further), so each object costs its own size rather than the frame's."""
    height, width = ids_now.shape
    top = max(0, min(now.box[0].start, future.box[0].start) - REGION_DILATION_PX)
    bottom = min(height, max(now.box[0].stop, future.box[0].stop) + REGION_DILATION_PX)
    left = max(0, min(now.box[1].start, future.box[1].start) - REGION_DILATION_PX)
    right = min(width, max(now.box[1].stop, future.box[1].stop) + REGION_DILATION_PX)
    box = (slice(top, bottom), slice(left, right))
    footprint = (ids_now[box] == object_id) | (ids_future[box] == object_id)
    return box, ndimage.binary_dilation(footprint, iterations=REGION_DILATION_PX)


@dataclass
class BackgroundFlow:
    """The simulator's flow [2, H, W] at a reference time's longest sampled horizon, zero where it
    is not finite; `at` scales it to a horizon (the camera's motion is close to constant over
    100 ms). Read once per window: the conversion costs more than the scaling of each horizon."""

    flow: np.ndarray
    valid: np.ndarray  # [H, W] bool: finite
    sampled_us: float  # 0 when the reference time has no sampled horizon of the grid step or more

    def at(self, horizon_ms: float) -> tuple[np.ndarray, np.ndarray]:
        if self.sampled_us == 0:
            return np.zeros_like(self.flow), np.zeros_like(self.valid)
        return self.flow * np.float32(horizon_ms * 1000.0 / self.sampled_us), self.valid


def background_flow(sequence: Sequence, reference: int) -> BackgroundFlow:
    sampled = sequence.horizon_us[reference]
    longest = int(np.argmax(sampled))
    if sampled[longest] < GRID_US:
        shape = (sequence.height, sequence.width)
        return BackgroundFlow(np.zeros((2, *shape), np.float32), np.zeros(shape, bool), 0.0)
    flow = sequence.future_flow[reference, longest].astype(np.float32).transpose(2, 0, 1)
    finite = np.isfinite(flow)
    return BackgroundFlow(np.where(finite, flow, np.float32(0)), finite.all(axis=0), float(sampled[longest]))


def flow_target(
    ids_now: np.ndarray | None, ids_future: np.ndarray, background: tuple[np.ndarray, np.ndarray]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(flow [2, H, W], valid [H, W], footprint, object region) over the full frame.

    Inside each object's region (its footprint at t and at t + h, dilated) the flow is the
    object's displacement between the two frames: backward warping reads at the pixel an object
    reaches the displacement that brings it there, and in the strip it uncovers one that reads
    background. Objects clipped by the border, or present at only one of the two times, keep the
    simulator's (scaled) flow."""
    flow, valid = background[0].copy(), background[1].copy()
    footprint = ids_future > 0
    if ids_now is not None:
        footprint |= ids_now > 0
    region = ndimage.binary_dilation(footprint, iterations=REGION_DILATION_PX) if footprint.any() else footprint
    if ids_now is None:
        return flow, valid, footprint, region
    now, future = object_places(ids_now), object_places(ids_future)
    for object_id in now.keys() & future.keys():
        if now[object_id].touches_border or future[object_id].touches_border:
            continue
        box, pixels = dilated_object(ids_now, ids_future, now[object_id], future[object_id], object_id)
        flow[(slice(None), *box)][:, pixels] = (future[object_id].centroid - now[object_id].centroid)[:, None]
        valid[box][pixels] = True
    return flow, valid, footprint, region


def future_events(
    sequence: Sequence, t_end: int, horizon_ms: float, crop: Crop, max_events: int, rng: np.random.Generator
) -> FutureEvents:
    future = sequence.event_range(t_end, t_end + int(horizon_ms * 1000))
    x = sequence.events_x[future].astype(np.int64) - crop.left
    y = sequence.events_y[future].astype(np.int64) - crop.top
    inside = np.flatnonzero((x >= 0) & (x < crop.width) & (y >= 0) & (y < crop.height))
    if inside.size > max_events:
        inside = np.sort(rng.choice(inside, max_events, replace=False))
    return FutureEvents(
        x=x[inside].astype(np.float32),
        y=y[inside].astype(np.float32),
        t_ms=(sequence.events_t[future][inside] - t_end).astype(np.float32) / 1000.0,
        on=sequence.events_on[future][inside],
    )


def fired_pixels(sequence: Sequence, time_us: int, crop: Crop) -> np.ndarray:
    """[crop.height, crop.width] bool: the crop's pixels with an event in [time_us −
    FIRED_HALF_SPAN_US, time_us + FIRED_HALF_SPAN_US)."""
    return cropped(sequence.event_pixels(time_us - FIRED_HALF_SPAN_US, time_us + FIRED_HALF_SPAN_US), crop)


NO_EVENTS = FutureEvents(*(np.empty(0, np.float32) for _ in range(3)), np.empty(0, bool))


def training_window(
    sequence: Sequence,
    reference: int,
    crop: Crop,
    horizons_ms: np.ndarray,
    full_voxel: np.ndarray,
    max_events: int,
    rng: np.random.Generator,
) -> TrainingWindow:
    """`full_voxel` is `reference_input(sequence, reference)`; future events (for contrast
    maximisation) are drawn only when `max_events` > 0."""
    t_end = int(sequence.ref_ts[reference])
    now = sequence.grid_index(t_end)
    ids_now = sequence.masks[now] if now is not None else None
    shape = (sequence.height, sequence.width)
    horizons = len(horizons_ms)
    future_mask = np.zeros((horizons, *shape), np.float32)
    future_valid = np.zeros(horizons, bool)
    flows = np.zeros((horizons, 2, *shape), np.float32)
    flow_valid = np.zeros((horizons, *shape), bool)
    footprints = np.zeros((horizons, *shape), bool)
    regions = np.zeros((horizons, *shape), bool)
    future_fired = np.zeros((horizons, crop.height, crop.width), bool)
    events = []
    background = background_flow(sequence, reference)
    for k, horizon in enumerate(horizons_ms):
        future_time = t_end + int(round(horizon * 1000))
        future_fired[k] = fired_pixels(sequence, future_time, crop)
        future = sequence.grid_index(future_time)
        if future is not None:
            ids_future = sequence.masks[future]
            future_valid[k] = True
            future_mask[k] = ids_future > 0
            flows[k], flow_valid[k], footprints[k], regions[k] = flow_target(
                ids_now, ids_future, background.at(float(horizon))
            )
        events.append(future_events(sequence, t_end, float(horizon), crop, max_events, rng) if max_events > 0 else NO_EVENTS)
    mask = (ids_now > 0).astype(np.float32) if ids_now is not None else np.zeros(shape, np.float32)
    return TrainingWindow(
        voxel=cropped(full_voxel, crop),
        mask=cropped(mask, crop),
        mask_valid=now is not None,
        fired=fired_pixels(sequence, t_end, crop),
        horizons_ms=np.asarray(horizons_ms, np.float32),
        future_mask=cropped(future_mask, crop),
        future_valid=future_valid,
        future_fired=future_fired,
        footprint=cropped(footprints, crop),
        future_flow=cropped(flows, crop),
        flow_valid=cropped(flow_valid, crop),
        object_region=cropped(regions, crop),
        future_events=events,
    )
