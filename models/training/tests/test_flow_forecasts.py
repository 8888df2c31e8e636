import numpy as np

from evgate_train.flow_forecasts import rigid_forecast, splat_forecast


def _square(top: int, left: int) -> np.ndarray:
    mask = np.zeros((30, 40), dtype=bool)
    mask[top : top + 6, left : left + 6] = True
    return mask


def _flow_inside(mask: np.ndarray, dx: float, dy: float) -> np.ndarray:
    flow = np.zeros((2, *mask.shape), dtype=np.float32)
    flow[0][mask], flow[1][mask] = dx, dy
    return flow


def test_both_move_an_object_by_its_flow():
    current = _square(5, 4)
    flow = _flow_inside(current, 9.0, 3.0)
    np.testing.assert_array_equal(rigid_forecast(current, flow), _square(8, 13))
    np.testing.assert_array_equal(splat_forecast(current, flow), _square(8, 13))


def test_rigid_ignores_a_blurred_border():
    current = _square(5, 4)
    flow = _flow_inside(current, 9.0, 0.0)
    flow[0][5, 4:10] = 2.0  # one row of the object sees a flow blurred towards the background's
    np.testing.assert_array_equal(rigid_forecast(current, flow), _square(5, 13))


def test_objects_leaving_the_image_are_clipped():
    current = _square(5, 30)
    forecast = rigid_forecast(current, _flow_inside(current, 8.0, 0.0))
    assert forecast.sum() == 6 * 2 and forecast[5:11, 38:40].all()
    assert not splat_forecast(current, _flow_inside(current, 40.0, 0.0)).any()
