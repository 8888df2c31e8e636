"""The small-object emphasis of the mask loss: how much each object's pixels weigh."""

import pytest
import torch

from evgate_train.losses import SMALL_OBJECT_MAX_FACTOR, bce_dice, small_object_emphasis
from evgate_train.objective import LossWeights, mask_emphasis


def test_small_objects_weigh_more_by_their_area_up_to_the_cap():
    target = torch.zeros(2, 1, 32, 32)
    target[0, 0, 0:10, 0:10] = 1.0  # 100 px: the reference area, no extra weight
    target[0, 0, 20:25, 20:25] = 1.0  # 25 px: 4 times
    target[1, 0, 3, 3] = target[1, 0, 4, 4] = 1.0  # 2 px touching diagonally, one object: capped
    emphasis = small_object_emphasis(target, reference_area=100)
    assert emphasis.shape == target.shape
    assert float(emphasis[0, 0, 0:10, 0:10].max()) == 0.0
    assert torch.all(emphasis[0, 0, 20:25, 20:25] == 3.0)
    assert float(emphasis[1, 0, 3, 3]) == float(emphasis[1, 0, 4, 4]) == SMALL_OBJECT_MAX_FACTOR - 1
    assert int((emphasis > 0).sum()) == 25 + 2  # background and the large object: none


def test_missing_a_small_object_costs_about_what_missing_a_large_one_does():
    large, small = torch.zeros(1, 1, 32, 32), torch.zeros(1, 1, 32, 32)
    large[..., 0:16, 0:16] = 1.0
    small[..., 0:8, 0:8] = 1.0
    valid = torch.ones(1, 1, 32, 32, dtype=torch.bool)
    background = torch.full((1, 1, 32, 32), -4.0)

    def missed(target: torch.Tensor, reference_area: float) -> float:
        emphasis = small_object_emphasis(target, reference_area) if reference_area else None
        # The BCE alone: Dice charges a miss of any size alike.
        return float(bce_dice(background, target, valid, dice_weight=0.0, emphasis=emphasis))

    assert missed(small, 0) < 0.3 * missed(large, 0)
    assert missed(small, 256) == pytest.approx(missed(large, 256), rel=0.2)


def test_the_fired_pixel_and_small_object_emphases_add_up():
    target = torch.zeros(1, 1, 8, 8)
    target[..., 2:4, 2:4] = 1.0
    fired = torch.zeros(1, 1, 8, 8, dtype=torch.bool)
    fired[..., 2, :] = True
    assert mask_emphasis(target, fired, LossWeights()) is None
    both = mask_emphasis(target, fired, LossWeights(fired_pixels=2.0, small_object_area=8.0))
    torch.testing.assert_close(both, 2.0 * fired + small_object_emphasis(target, 8.0))
    assert float(both[0, 0, 2, 2]) == 2.0 + 1.0
