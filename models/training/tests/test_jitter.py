import dataclasses

import numpy as np
import pytest

from evgate_train.augment import Augmentation
from evgate_train.jitter import EventJitter, JitterRangeError, JitterRanges
from evgate_train.sequence import load_sequence
from evgate_train.streams import StreamSampler
from evgate_train.windows import reference_input

WIDTH, HEIGHT = 96, 64


def _events(count=200_000, seed=0):
    rng = np.random.default_rng(seed)
    t = np.sort(rng.integers(0, 50_000, count))
    x = rng.integers(0, WIDTH, count).astype(np.uint16)
    y = rng.integers(0, HEIGHT, count).astype(np.uint16)
    on = rng.random(count) < 0.5
    return t, x, y, on


def test_no_jitter_leaves_the_events_and_the_voxel_grid_alone(synthetic_dir):
    events = _events()
    for before, after in zip(events, EventJitter().events(*events, WIDTH, HEIGHT, 3)):
        np.testing.assert_array_equal(before, after)
    sequence = load_sequence(sorted(synthetic_dir.rglob("*.npz"))[0])
    np.testing.assert_array_equal(reference_input(sequence, 2), reference_input(sequence, 2, EventJitter()))


def test_dropout_and_polarity_flips_take_their_shares():
    t, x, y, on = _events()
    jittered = EventJitter(dropout=0.3, polarity_flip=0.08, seed=11)
    kept_t, kept_x, kept_y, kept_on = jittered.events(t, x, y, on, WIDTH, HEIGHT, 5)
    assert kept_t.size / t.size == pytest.approx(0.7, abs=0.005)
    # Events are only removed, in order: find each kept one in the original by its time and pixel.
    original = {(int(a), int(b), int(c)): bool(d) for a, b, c, d in zip(t, x, y, on)}
    flipped = np.mean([original[(int(a), int(b), int(c))] != bool(d) for a, b, c, d in zip(kept_t, kept_x, kept_y, kept_on)])
    assert flipped == pytest.approx(0.08, abs=0.005)
    assert np.all(np.diff(kept_t) >= 0)


def test_the_local_rate_follows_a_smooth_field_within_its_range():
    jittered = EventJitter(min_rate=0.25, seed=3)
    field = jittered.rate_field(WIDTH, HEIGHT)
    assert field.shape == (HEIGHT, WIDTH)
    assert field.min() >= 0.25 - 1e-6 and field.max() <= 1.0 + 1e-6
    assert field.max() - field.min() > 0.1  # the rate does vary over the sensor
    assert np.abs(np.diff(field, axis=0)).max() < 0.05 and np.abs(np.diff(field, axis=1)).max() < 0.05
    t, x, y, on = _events(400_000)
    _, kept_x, kept_y, _ = jittered.events(t, x, y, on, WIDTH, HEIGHT, 0)
    for rows, cols in [(slice(0, 16), slice(0, 24)), (slice(48, 64), slice(72, 96))]:
        inside = lambda xs, ys: np.count_nonzero((ys >= rows.start) & (ys < rows.stop) & (xs >= cols.start) & (xs < cols.stop))  # noqa: E731
        assert inside(kept_x, kept_y) / inside(x, y) == pytest.approx(field[rows, cols].mean(), abs=0.02)


def test_a_window_jitters_alike_every_time_and_unlike_other_windows():
    events = _events(20_000)
    jittered = EventJitter(dropout=0.4, polarity_flip=0.1, min_rate=0.5, seed=9)
    first = jittered.events(*events, WIDTH, HEIGHT, 7)
    for a, b in zip(first, jittered.events(*events, WIDTH, HEIGHT, 7)):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(first[0], jittered.events(*events, WIDTH, HEIGHT, 8)[0])


def test_draws_stay_within_their_ranges_and_bad_ranges_are_refused():
    rng = np.random.default_rng(1)
    ranges = JitterRanges(max_dropout=0.4, max_polarity_flip=0.05, min_rate=0.5)
    for _ in range(200):
        drawn = EventJitter.draw(rng, ranges)
        assert 0 <= drawn.dropout < 0.4 and 0 <= drawn.polarity_flip <= 0.05 and 0.5 <= drawn.min_rate <= 1
    with pytest.raises(JitterRangeError, match="maximum dropout 1.0: accepted 0 to below 1"):
        JitterRanges(max_dropout=1.0)
    with pytest.raises(JitterRangeError, match="maximum polarity flip 0.7"):
        JitterRanges(max_polarity_flip=0.7)
    with pytest.raises(JitterRangeError, match="minimum local rate 0.0"):
        JitterRanges(min_rate=0.0)


def _sampler(synthetic_dir, jitter):
    return StreamSampler(sorted(synthetic_dir.rglob("*.npz")), 2, 2, 48, 96, 3, 0, True, 5, jitter)


def test_a_jittered_run_plays_the_same_windows_with_other_input(synthetic_dir):
    plain, jittered = _sampler(synthetic_dir, None), _sampler(synthetic_dir, JitterRanges())
    for _ in range(6):
        plain_step, jittered_step = plain.step(), jittered.step()
        for a, b in zip(plain.cursors, jittered.cursors):
            assert (a.sequence, a.crop, a.next_reference) == (b.sequence, b.crop, b.next_reference)
            assert dataclasses.replace(b.augmentation, jitter=EventJitter()) == a.augmentation
            assert not b.augmentation.jitter.is_identity
        for a, b in zip(plain_step.windows, jittered_step.windows):
            np.testing.assert_array_equal(a.mask, b.mask)
            np.testing.assert_array_equal(a.horizons_ms, b.horizons_ms)
            assert not np.array_equal(a.voxel, b.voxel)


def test_a_cursor_keeps_its_jitter_and_one_saved_without_jitter_still_loads(synthetic_dir):
    sampler = _sampler(synthetic_dir, JitterRanges())
    sampler.step()
    state = sampler.state_dict()
    resumed = _sampler(synthetic_dir, JitterRanges())
    resumed.load_state_dict(state)
    assert resumed.cursors == sampler.cursors
    np.testing.assert_array_equal(resumed.step().windows[0].voxel, sampler.step().windows[0].voxel)

    old = dict(state)
    del old["jitter-rng"]
    old["cursors"] = [{**c, "augmentation": {k: v for k, v in c["augmentation"].items() if k != "jitter"}} for c in state["cursors"]]
    legacy = _sampler(synthetic_dir, None)
    legacy.load_state_dict(old)
    assert all(c.augmentation.jitter == EventJitter() for c in legacy.cursors)
    assert Augmentation.from_dict({"flip_horizontal": True, "flip_vertical": False, "invert_polarity": True}) == Augmentation(True, False, True)
