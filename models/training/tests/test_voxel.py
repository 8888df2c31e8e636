"""The voxel grid formula shared with evgate-core (crates/evgate-core/src/voxel.rs)."""

import numpy as np
import pytest

from evgate_train.voxel import BinCountError, EventOutOfSensorError, accumulate, normalise, voxel_grid


def test_events_split_linearly_between_the_two_bins_and_grid_is_padded():
    # Window [0, 50 ms]: an ON event at 12.5 ms (tau = 0.25), an OFF event at the end (tau = 1).
    t = np.array([12_500, 50_000], np.int64)
    grid = accumulate(t, np.array([3, 5]), np.array([2, 7]), np.array([1, 0]), 50_000, width=21, height=13)
    assert grid.shape == (2, 16, 32)
    assert grid[0, 2, 3] == pytest.approx(0.75) and grid[1, 2, 3] == pytest.approx(0.25)
    assert grid[0, 7, 5] == 0.0 and grid[1, 7, 5] == pytest.approx(-1.0)
    assert np.count_nonzero(grid) == 3


def test_window_includes_both_ends_and_nothing_outside():
    t = np.array([-1, 0, 50_000, 50_001], np.int64)
    grid = accumulate(t, np.zeros(4, int), np.zeros(4, int), np.ones(4, int), 50_000, width=16, height=16)
    assert grid[0, 0, 0] == pytest.approx(1.0) and grid[1, 0, 0] == pytest.approx(1.0)


def test_non_zero_cells_are_standardised_with_sample_std():
    grid = np.zeros((2, 16, 16), np.float32)
    grid[0, 0, :3] = [1.0, 2.0, 3.0]
    normalise(grid)
    # mean 2, sample std 1 (n - 1 denominator): -1, 0, 1; zero cells stay zero.
    np.testing.assert_allclose(grid[0, 0, :3], [-1.0, 0.0, 1.0], atol=1e-6)
    assert np.count_nonzero(grid) == 2


def test_single_non_zero_cell_only_loses_its_mean():
    grid = np.zeros((2, 16, 16), np.float32)
    grid[1, 4, 4] = 0.5
    normalise(grid)
    assert np.count_nonzero(grid) == 0


def test_inverting_polarity_negates_the_normalised_grid():
    rng = np.random.default_rng(3)
    t = np.sort(rng.integers(0, 50_001, 500))
    x, y, on = rng.integers(0, 30, 500), rng.integers(0, 20, 500), rng.integers(0, 2, 500)
    grid = voxel_grid(t, x, y, on, 50_000, 30, 20)
    inverted = voxel_grid(t, x, y, 1 - on, 50_000, 30, 20)
    np.testing.assert_allclose(inverted, -grid, atol=1e-6)


def test_event_outside_the_sensor_is_reported():
    with pytest.raises(EventOutOfSensorError, match="x = 40, y = 1 lies outside the 30x20 sensor"):
        accumulate(np.array([10]), np.array([40]), np.array([1]), np.array([1]), 50_000, 30, 20)


def test_finer_grids_split_each_event_between_the_two_bins_around_its_time():
    # 5 bins centred at tau = 0, 0.25, 0.5, 0.75, 1: tau = 0.375 lies halfway between bins 1 and 2.
    t = np.array([18_750, 50_000], np.int64)
    grid = accumulate(t, np.array([3, 5]), np.array([2, 7]), np.array([1, 0]), 50_000, width=21, height=13, bins=5)
    assert grid.shape == (5, 16, 32)
    np.testing.assert_allclose(grid[:, 2, 3], [0.0, 0.5, 0.5, 0.0, 0.0])
    np.testing.assert_allclose(grid[:, 7, 5], [0.0, 0.0, 0.0, 0.0, -1.0])


def test_every_bin_count_keeps_each_events_sign_in_total():
    rng = np.random.default_rng(3)
    t = rng.integers(0, 50_001, 500)
    x, y, on = rng.integers(0, 20, 500), rng.integers(0, 12, 500), rng.integers(0, 2, 500)
    two = accumulate(t, x, y, on, 50_000, width=20, height=12)
    for bins in (2, 3, 7):
        np.testing.assert_allclose(accumulate(t, x, y, on, 50_000, 20, 12, bins).sum(axis=0), two.sum(axis=0), atol=1e-4)


def test_fewer_than_two_bins_is_refused():
    with pytest.raises(BinCountError, match="voxel bins 1: accepted 2 or more"):
        accumulate(np.array([0]), np.array([0]), np.array([0]), np.array([1]), 50_000, 16, 16, bins=1)
