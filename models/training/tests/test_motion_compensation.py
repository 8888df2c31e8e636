"""The ego-motion-compensated input channel (evgate_train.motion_compensation)."""

import numpy as np

from evgate_train.motion_compensation import MIN_FIT_EVENTS, compensated_image, fit_velocity
from evgate_train.voxel import WINDOW_US

WIDTH, HEIGHT = 96, 64


def sweeping_texture(velocity: tuple[float, float], count: int = 6000, seed: int = 0):
    """Events of a random static texture that the camera's motion sweeps at `velocity` (px/s)
    over the window ending at 50 ms: each texture point fires where it is at its event's time."""
    rng = np.random.default_rng(seed)
    points = rng.uniform([20, 15], [76, 49], (40, 2))
    t = np.sort(rng.integers(0, WINDOW_US + 1, count))
    which = rng.integers(0, len(points), count)
    seconds = (t - WINDOW_US) / 1e6
    x = np.floor(points[which, 0] + velocity[0] * seconds).astype(np.int64)
    y = np.floor(points[which, 1] + velocity[1] * seconds).astype(np.int64)
    return t, x, y


def sum_of_squares(image: np.ndarray) -> float:
    counts = image / image[image > 0].min()
    return float((counts * counts).sum())


def test_the_fit_finds_the_velocity_that_sweeps_a_static_texture():
    for velocity in ((300.0, -140.0), (-520.0, 60.0), (0.0, 0.0)):
        t, x, y = sweeping_texture(velocity)
        fitted = fit_velocity(t, x, y, WINDOW_US, WIDTH, HEIGHT)
        assert np.abs(fitted - velocity).max() <= 40.0, (velocity, fitted)


def test_the_compensated_image_is_sharper_than_the_raw_one():
    t, x, y = sweeping_texture((300.0, -140.0))
    compensated = compensated_image(t, x, y, WINDOW_US, WIDTH, HEIGHT)
    raw = np.zeros((HEIGHT, WIDTH))
    np.add.at(raw, (y, x), 1.0)
    assert compensated.shape == (1, 64, 96) and compensated.dtype == np.float32
    assert sum_of_squares(compensated[0]) > 3 * sum_of_squares(raw)
    # Divided by the mean of its non-zero pixels.
    assert compensated[compensated > 0].mean() == np.float32(1.0)


def test_a_small_object_moving_otherwise_does_not_capture_the_fit():
    t, x, y = sweeping_texture((300.0, 0.0))
    object_t, object_x, object_y = sweeping_texture((-300.0, 0.0), count=600, seed=1)
    order = np.argsort(np.concatenate([t, object_t]), kind="stable")
    all_t, all_x, all_y = (np.concatenate(pair)[order] for pair in ((t, object_t), (x, object_x), (y, object_y)))
    assert np.abs(fit_velocity(all_t, all_x, all_y, WINDOW_US, WIDTH, HEIGHT) - (300.0, 0.0)).max() <= 40.0


def test_windows_with_too_few_events_keep_zero_velocity_and_empty_windows_an_empty_image():
    t, x, y = sweeping_texture((300.0, 0.0), count=MIN_FIT_EVENTS - 1)
    assert np.array_equal(fit_velocity(t, x, y, WINDOW_US, WIDTH, HEIGHT), [0.0, 0.0])
    empty = np.empty(0, np.int64)
    assert not compensated_image(empty, empty, empty, WINDOW_US, WIDTH, HEIGHT).any()


def test_events_outside_the_window_are_ignored():
    t, x, y = sweeping_texture((300.0, -140.0))
    late = np.concatenate([t, np.full(50, WINDOW_US + 1)])
    late_x, late_y = np.concatenate([x, np.full(50, 5)]), np.concatenate([y, np.full(50, 5)])
    np.testing.assert_array_equal(
        compensated_image(late, late_x, late_y, WINDOW_US, WIDTH, HEIGHT), compensated_image(t, x, y, WINDOW_US, WIDTH, HEIGHT)
    )
