from types import SimpleNamespace

import torch

from evgate_train.objective import LossWeights, true_mask_warp_term

SIZE = 32
SHIFT_PX = 6


def _square(left: int) -> torch.Tensor:
    mask = torch.zeros(SIZE, SIZE)
    mask[10:18, left : left + 8] = 1.0
    return mask


def _batch(mask_valid: bool) -> SimpleNamespace:
    """One window, two horizons: the square moves right by SHIFT_PX per horizon step."""
    return SimpleNamespace(
        mask=_square(4).view(1, 1, SIZE, SIZE),
        future_mask=torch.stack([_square(4 + SHIFT_PX), _square(4 + 2 * SHIFT_PX)]).unsqueeze(0),
        mask_valid=torch.tensor([mask_valid]),
        future_valid=torch.tensor([[True, True]]),
    )


def _flow(dx_per_horizon: float) -> torch.Tensor:
    flow = torch.zeros(2, 2, SIZE, SIZE)
    flow[0, 0] = dx_per_horizon
    flow[1, 0] = 2 * dx_per_horizon
    return flow


def test_the_true_flow_scores_lower_than_no_flow_and_the_reverse_flow():
    weights = LossWeights(dice=1.0, positive=3.0)
    batch = _batch(mask_valid=True)
    true = true_mask_warp_term(_flow(SHIFT_PX), batch, weights)
    still = true_mask_warp_term(_flow(0.0), batch, weights)
    reverse = true_mask_warp_term(_flow(-SHIFT_PX), batch, weights)
    assert float(true) < float(still) < float(reverse) + 1e-6


def test_the_gradient_pushes_the_flow_towards_the_motion():
    flow = _flow(SHIFT_PX / 2).requires_grad_(True)
    true_mask_warp_term(flow, _batch(mask_valid=True), LossWeights(dice=1.0, positive=3.0)).backward()
    assert float(flow.grad[:, 0].sum()) < 0


def test_windows_without_a_true_current_mask_add_nothing():
    term = true_mask_warp_term(_flow(0.0), _batch(mask_valid=False), LossWeights(dice=1.0, positive=3.0))
    assert float(term) == 0.0
