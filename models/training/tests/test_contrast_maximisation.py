import numpy as np
import torch
from synthetic_sequence import HEIGHT, SPEED_PX_PER_MS, WIDTH, events

from evgate_train.contrast_maximisation import average_timestamp_loss


def _future_window(start_ms: float, horizon_ms: float):
    t, x, y, on = events(seed=2)
    inside = (t >= start_ms * 1000) & (t <= (start_ms + horizon_ms) * 1000)
    return (
        torch.from_numpy(x[inside].astype(np.float32)),
        torch.from_numpy(y[inside].astype(np.float32)),
        torch.from_numpy(((t[inside] - start_ms * 1000) / 1000).astype(np.float32)),
        torch.from_numpy(on[inside].astype(bool)),
    )


def test_true_flow_scores_lower_than_zero_flow_on_simulated_events():
    x, y, t_ms, on = _future_window(100.0, 80.0)
    assert len(x) > 200
    true_velocity = torch.zeros(2, HEIGHT, WIDTH)
    true_velocity[0] = SPEED_PX_PER_MS  # only the square's pixels fire, so a uniform field is exact
    zero = average_timestamp_loss(x, y, t_ms, on, torch.zeros(2, HEIGHT, WIDTH), 80.0)
    true = average_timestamp_loss(x, y, t_ms, on, true_velocity, 80.0)
    wrong_direction = average_timestamp_loss(x, y, t_ms, on, -true_velocity, 80.0)
    assert float(true) < float(zero) < float(wrong_direction)


def test_loss_has_a_gradient_towards_the_true_flow():
    x, y, t_ms, on = _future_window(100.0, 80.0)
    velocity = torch.full((2, HEIGHT, WIDTH), 0.0)
    velocity[0] = 0.5 * SPEED_PX_PER_MS
    velocity.requires_grad_(True)
    average_timestamp_loss(x, y, t_ms, on, velocity, 80.0).backward()
    # Increasing the horizontal velocity towards the truth must lower the loss.
    assert float(velocity.grad[0].sum()) < 0
