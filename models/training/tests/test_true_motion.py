import numpy as np

from evgate_train.true_motion import KINEMATICS_STEP_MS, REACH_PX, true_kinematics_forecast, true_motion_forecast


def _square(mask: np.ndarray, row: int, col: int, value=True, side: int = 6) -> None:
    mask[row : row + side, col : col + side] = value


def test_each_component_moves_by_its_objects_true_displacement():
    truth_now, truth_future = np.zeros((40, 60), np.uint8), np.zeros((40, 60), np.uint8)
    _square(truth_now, 5, 5, 1)
    _square(truth_future, 8, 12, 1)  # object 1 moves 3 down, 7 right
    _square(truth_now, 25, 40, 2)
    _square(truth_future, 25, 30, 2)  # object 2 moves 10 left
    current = np.zeros((40, 60), bool)
    current[5:9, 5:11] = True  # the top two thirds of object 1
    current[22:26, 38:42] = True  # off object 2 by up to REACH_PX
    forecast = true_motion_forecast(current, truth_now, truth_future)
    expected = np.zeros_like(current)
    expected[8:12, 12:18] = True
    expected[22:26, 28:32] = True
    np.testing.assert_array_equal(forecast, expected)


def test_a_component_near_no_object_stays_and_one_whose_object_left_is_dropped():
    truth_now, truth_future = np.zeros((40, 60), np.uint8), np.zeros((40, 60), np.uint8)
    _square(truth_now, 5, 5, 3)  # gone by t + h
    current = np.zeros((40, 60), bool)
    _square(current, 5, 5)
    far = 5 + 6 + REACH_PX + 2
    _square(current, far, far)
    forecast = true_motion_forecast(current, truth_now, truth_future)
    expected = np.zeros_like(current)
    _square(expected, far, far)
    np.testing.assert_array_equal(forecast, expected)


def test_the_kinematics_oracle_carries_each_objects_past_velocity_and_acceleration_on():
    # Object 1 keeps a velocity of 2 px right per step; object 2 falls with 1 px per step squared
    # (rows 10, 11, 13 at t - 2s, t - s, t: 3 and 4 rows further at the next two steps).
    past = tuple(np.zeros((60, 60), np.uint8) for _ in range(3))
    for step, ids in enumerate(past):
        _square(ids, 30, 10 + 2 * step, 1)
        _square(ids, (10, 11, 13)[step], 40, 2)
    current = past[2] > 0
    forecast = true_kinematics_forecast(current, past, horizon_ms=2 * KINEMATICS_STEP_MS)
    expected = np.zeros_like(current)
    _square(expected, 30, 14 + 4)
    _square(expected, 13 + 3 + 4, 40)
    np.testing.assert_array_equal(forecast, expected)


def test_the_kinematics_oracle_keeps_still_an_object_missing_from_its_history():
    past = tuple(np.zeros((40, 60), np.uint8) for _ in range(3))
    _square(past[1], 5, 8, 1)
    _square(past[2], 5, 10, 1)  # not there at t - 2s
    current = past[2] > 0
    forecast = true_kinematics_forecast(current, past, horizon_ms=100.0)
    np.testing.assert_array_equal(forecast, current)
