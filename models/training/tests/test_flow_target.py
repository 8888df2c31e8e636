"""The flow targets, computed per object inside its bounding box, equal the same targets
computed over the whole frame."""

import numpy as np
from scipy import ndimage

from evgate_train.windows import REGION_DILATION_PX, flow_target


def whole_frame_flow_target(ids_now, ids_future, background):
    flow, valid = background[0].copy(), background[1].copy()
    footprint = (ids_future > 0) | (ids_now > 0)
    region = ndimage.binary_dilation(footprint, iterations=REGION_DILATION_PX) if footprint.any() else footprint
    height, width = ids_now.shape

    def place(ids, object_id):
        rows, cols = np.nonzero(ids == object_id)
        touches = rows.min() == 0 or cols.min() == 0 or rows.max() == height - 1 or cols.max() == width - 1
        return np.array([cols.mean(), rows.mean()], np.float32), touches

    shared = set(np.unique(ids_now)) & set(np.unique(ids_future)) - {0}
    for object_id in shared:
        (now, now_touches), (future, future_touches) = place(ids_now, object_id), place(ids_future, object_id)
        if now_touches or future_touches:
            continue
        pixels = ndimage.binary_dilation((ids_now == object_id) | (ids_future == object_id), iterations=REGION_DILATION_PX)
        flow[:, pixels] = (future - now)[:, None]
        valid[pixels] = True
    return flow, valid, footprint, region


def random_ids(rng, shape, objects):
    ids = np.zeros(shape, np.uint8)
    for object_id in objects:
        top, left = rng.integers(-6, shape[0]), rng.integers(-6, shape[1])
        height, width = rng.integers(1, 20, size=2)
        ids[max(0, top) : max(0, top + height), max(0, left) : max(0, left + width)] = object_id
        if rng.random() < 0.5:  # a second, disjoint part of the same object
            top, left = rng.integers(0, shape[0]), rng.integers(0, shape[1])
            ids[top : top + 3, left : left + 4] = object_id
    return ids


def test_the_per_object_flow_targets_equal_the_whole_frame_ones():
    rng = np.random.default_rng(3)
    shape = (40, 56)
    for _ in range(300):
        now = random_ids(rng, shape, rng.choice([1, 2, 3, 4], rng.integers(0, 4), replace=False))
        future = random_ids(rng, shape, rng.choice([1, 2, 3, 4], rng.integers(0, 4), replace=False))
        background = (rng.normal(size=(2, *shape)).astype(np.float32), rng.random(shape) < 0.9)
        got = flow_target(now, future, background)
        expected = whole_frame_flow_target(now, future, background)
        for name, a, b in zip(("flow", "valid", "footprint", "region"), got, expected):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-5, err_msg=name)
