"""The focal exponent of the mask BCE: confident right answers stop counting, wrong ones do not."""

import math

import pytest
import torch

from evgate_train.losses import bce_dice


def _bce(logit: float, target: float, focal_gamma: float) -> float:
    logits, targets = torch.tensor([[[[logit]]]]), torch.tensor([[[[target]]]])
    return float(bce_dice(logits, targets, torch.ones_like(targets, dtype=torch.bool), 0.0, focal_gamma=focal_gamma))


@pytest.mark.parametrize("target, sign", [(0.0, 1.0), (1.0, -1.0)])
def test_each_pixel_is_scaled_by_the_probability_it_gives_the_wrong_class(target, sign):
    # A pixel with logit 4 away from its class: p_t = sigmoid(4) when right, 1 - sigmoid(4) when wrong.
    right, wrong = -sign * 4.0, sign * 4.0
    p_right = 1.0 / (1.0 + math.exp(-4.0))
    assert _bce(right, target, 2.0) == pytest.approx(_bce(right, target, 0.0) * (1.0 - p_right) ** 2, rel=1e-5)
    assert _bce(wrong, target, 2.0) == pytest.approx(_bce(wrong, target, 0.0) * p_right**2, rel=1e-5)
    assert _bce(right, target, 2.0) < 1e-3 * _bce(wrong, target, 2.0)


def test_gamma_zero_is_plain_bce():
    logits, target = torch.randn(2, 1, 8, 8), (torch.rand(2, 1, 8, 8) > 0.7).float()
    valid = torch.ones_like(target, dtype=torch.bool)
    plain = torch.nn.functional.binary_cross_entropy_with_logits(logits, target)
    assert float(bce_dice(logits, target, valid, 0.0, focal_gamma=0.0)) == pytest.approx(float(plain), rel=1e-6)
