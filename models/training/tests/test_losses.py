import torch

from evgate_train.losses import charbonnier_smoothness, flow_l1_by_region


def _object(size: int = 32, side: int = 4) -> torch.Tensor:
    region = torch.zeros(1, size, size, dtype=torch.bool)
    region[0, 10 : 10 + side, 10 : 10 + side] = True
    return region


def test_object_and_background_errors_weigh_alike_whatever_their_areas():
    region = _object()
    target = torch.zeros(1, 2, 32, 32)
    target[:, 0][region] = 5.0
    valid = torch.ones(1, 32, 32, dtype=torch.bool)
    # A flow that misses only the small object: a plain mean over pixels would call it 1.6 % wrong.
    still = torch.zeros(1, 2, 32, 32)
    assert float(flow_l1_by_region(still, target, valid, region)) == 5.0
    # And one that gets only the object right while the background is off by 1 px.
    background_off = target.clone()
    background_off[:, 1][~region] = 1.0
    assert float(flow_l1_by_region(background_off, target, valid, region)) == 1.0
    # Invalid pixels count nowhere.
    assert float(flow_l1_by_region(still, target, ~region, region)) == 0.0


def test_smoothness_is_not_charged_across_object_edges():
    region = _object(side=8)
    flow = torch.zeros(1, 2, 32, 32)
    flow[:, 0][region] = 5.0
    across_edges = charbonnier_smoothness(flow)
    within_parts = charbonnier_smoothness(flow, region)
    assert float(across_edges) > 0.1
    assert float(within_parts) < 1e-2
    # A jump inside one part is still charged.
    flow[:, 0, :, 20:] += 3.0
    assert float(charbonnier_smoothness(flow, region)) > 0.05
