"""Supervised losses: BCE (+ Dice) on mask logits, L1 on flow by region, Charbonnier smoothness."""

import numpy as np
import torch
import torch.nn.functional as F
from scipy import ndimage

from .metrics import EIGHT_CONNECTED

CHARBONNIER_EPSILON = 1e-3
# The most a small object's pixels weigh against a large one's (`small_object_emphasis`): a
# component of a few pixels would otherwise outweigh whole frames.
SMALL_OBJECT_MAX_FACTOR = 8.0


def bce_dice(
    logits: torch.Tensor,
    target: torch.Tensor,
    valid: torch.Tensor,
    dice_weight: float,
    positive_weight: float = 1.0,
    emphasis: torch.Tensor | None = None,
    focal_gamma: float = 0.0,
) -> torch.Tensor:
    """BCE over valid pixels (IMO pixels weighted by `positive_weight`, and each by 1 + its
    `emphasis` where given) as a weighted mean, plus `dice_weight` x soft Dice loss; tensors
    share one shape. `focal_gamma` > 0 scales each pixel's BCE by (1 - p_t)^gamma, p_t the
    probability given to its true class (the focal loss, Lin et al., ICCV 2017)."""
    valid = valid.to(logits.dtype)
    bce = F.binary_cross_entropy_with_logits(
        logits, target, reduction="none", pos_weight=torch.tensor(positive_weight, dtype=logits.dtype, device=logits.device)
    )
    if focal_gamma > 0:
        probability = torch.sigmoid(logits)
        true_class_probability = probability * target + (1.0 - probability) * (1.0 - target)
        bce = bce * (1.0 - true_class_probability).pow(focal_gamma)
    weight = valid if emphasis is None else valid * (1.0 + emphasis.to(logits.dtype))
    loss = (bce * weight).sum() / weight.sum().clamp_min(1.0)
    if dice_weight > 0:
        probability = torch.sigmoid(logits) * valid
        overlap = (probability * target).flatten(1).sum(1)
        total = probability.flatten(1).sum(1) + (target * valid).flatten(1).sum(1)
        dice = 1.0 - (2.0 * overlap + 1.0) / (total + 1.0)
        loss = loss + dice_weight * dice.mean()
    return loss


def small_object_emphasis(target: torch.Tensor, reference_area: float) -> torch.Tensor:
    """Extra BCE weight (an `emphasis` of `bce_dice`) of each IMO pixel of `target` [..., H, W]:
    reference_area / the area of its 8-connected component, less 1, between 0 and
    SMALL_OBJECT_MAX_FACTOR - 1. The frame-mean mIoU and R@0.5 count a frame or an instance
    whatever its size, but a pooled BCE spends its weight where the pixels are: on large objects."""
    truth = target.detach().cpu().numpy() > 0.5
    emphasis = np.zeros(truth.shape, np.float32)
    for index in np.ndindex(truth.shape[:-2]):
        labels, count = ndimage.label(truth[index], structure=EIGHT_CONNECTED)
        if count == 0:
            continue
        areas = np.bincount(labels.ravel())[1:]
        factor = np.clip(reference_area / areas, 1.0, SMALL_OBJECT_MAX_FACTOR) - 1.0
        emphasis[index] = np.concatenate([[0.0], factor])[labels]
    return torch.from_numpy(emphasis).to(target.device)


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
