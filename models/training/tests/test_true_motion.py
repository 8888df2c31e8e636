import numpy as np

from evgate_train.true_motion import REACH_PX, true_motion_forecast


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
