"""Supervised losses: BCE (+ Dice) on mask logits, L1 on flow by region, Charbonnier smoothness."""

import torch
import torch.nn.functional as F

CHARBONNIER_EPSILON = 1e-3


def bce_dice(
    logits: torch.Tensor,
    target: torch.Tensor,
    valid: torch.Tensor,
    dice_weight: float,
    positive_weight: float = 1.0,
    emphasis: torch.Tensor | None = None,
) -> torch.Tensor:
    """BCE over valid pixels (IMO pixels weighted by `positive_weight`, and each by 1 + its
    `emphasis` where given) as a weighted mean, plus `dice_weight` x soft Dice loss; tensors
    share one shape."""
    valid = valid.to(logits.dtype)
    bce = F.binary_cross_entropy_with_logits(
        logits, target, reduction="none", pos_weight=torch.tensor(positive_weight, dtype=logits.dtype, device=logits.device)
    )
    weight = valid if emphasis is None else valid * (1.0 + emphasis.to(logits.dtype))
    loss = (bce * weight).sum() / weight.sum().clamp_min(1.0)
    if dice_weight > 0:
        probability = torch.sigmoid(logits) * valid
        overlap = (probability * target).flatten(1).sum(1)
        total = probability.flatten(1).sum(1) + (target * valid).flatten(1).sum(1)
        dice = 1.0 - (2.0 * overlap + 1.0) / (total + 1.0)
        loss = loss + dice_weight * dice.mean()
    return loss


def flow_l1_by_region(flow: torch.Tensor, target: torch.Tensor, valid: torch.Tensor, region: torch.Tensor) -> torch.Tensor:
    """Mean end-point L1 over the valid pixels of `region` plus that over the valid pixels
    outside it; flow/target [N, 2, H, W], valid/region [N, H, W] bool. Objects cover a few per
    cent of a frame: one mean over all pixels would leave their motion untaught."""
    error = (flow - target).abs().sum(1)
    total = flow.new_zeros(())
    for part in (valid & region, valid & ~region):
        weight = part.to(flow.dtype)
        total = total + (error * weight).sum() / weight.sum().clamp_min(1.0)
    return total


def charbonnier_smoothness(flow: torch.Tensor, *labels: torch.Tensor) -> torch.Tensor:
    """Charbonnier penalty on the first-order spatial differences of flow [N, 2, H, W], left out
    between neighbours whose value differs in any of `labels` ([N, H, W] bool): motion is
    discontinuous at object edges."""
    dx = flow[..., :, 1:] - flow[..., :, :-1]
    dy = flow[..., 1:, :] - flow[..., :-1, :]
    keep_x = torch.ones_like(dx[:, 0], dtype=torch.bool)
    keep_y = torch.ones_like(dy[:, 0], dtype=torch.bool)
    for label in labels:
        keep_x &= label[..., :, 1:] == label[..., :, :-1]
        keep_y &= label[..., 1:, :] == label[..., :-1, :]
    penalty_x = torch.sqrt((dx**2).sum(1) + CHARBONNIER_EPSILON**2) * keep_x
    penalty_y = torch.sqrt((dy**2).sum(1) + CHARBONNIER_EPSILON**2) * keep_y
    return penalty_x.sum() / keep_x.sum().clamp_min(1) + penalty_y.sum() / keep_y.sum().clamp_min(1)
