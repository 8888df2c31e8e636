"""Supervised losses: BCE (+ Dice) on mask logits, L1 on flow, Charbonnier smoothness."""

import torch
import torch.nn.functional as F

CHARBONNIER_EPSILON = 1e-3


def bce_dice(
    logits: torch.Tensor, target: torch.Tensor, valid: torch.Tensor, dice_weight: float, positive_weight: float = 1.0
) -> torch.Tensor:
    """BCE over valid pixels (IMO pixels weighted by `positive_weight`) plus `dice_weight` x
    soft Dice loss; tensors share one shape."""
    valid = valid.to(logits.dtype)
    bce = F.binary_cross_entropy_with_logits(
        logits, target, reduction="none", pos_weight=torch.tensor(positive_weight, dtype=logits.dtype, device=logits.device)
    )
    loss = (bce * valid).sum() / valid.sum().clamp_min(1.0)
    if dice_weight > 0:
        probability = torch.sigmoid(logits) * valid
        overlap = (probability * target).flatten(1).sum(1)
        total = probability.flatten(1).sum(1) + (target * valid).flatten(1).sum(1)
        dice = 1.0 - (2.0 * overlap + 1.0) / (total + 1.0)
        loss = loss + dice_weight * dice.mean()
    return loss


def flow_l1(flow: torch.Tensor, target: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Mean end-point L1 over valid pixels; flow/target [N, 2, H, W], valid [N, H, W]."""
    valid = valid.to(flow.dtype)
    error = (flow - target).abs().sum(1)
    return (error * valid).sum() / valid.sum().clamp_min(1.0)


def charbonnier_smoothness(flow: torch.Tensor) -> torch.Tensor:
    """Charbonnier penalty on the first-order spatial differences of flow [N, 2, H, W]."""
    dx = flow[..., :, 1:] - flow[..., :, :-1]
    dy = flow[..., 1:, :] - flow[..., :-1, :]
    penalty_x = torch.sqrt((dx**2).sum(1) + CHARBONNIER_EPSILON**2)
    penalty_y = torch.sqrt((dy**2).sum(1) + CHARBONNIER_EPSILON**2)
    return penalty_x.mean() + penalty_y.mean()
