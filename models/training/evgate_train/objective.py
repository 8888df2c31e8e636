"""The training objective of one window: supervised mask and flow terms plus the
unsupervised contrast-maximisation term (paper, appendix: L = w_sup L_sup + w_unsup L_unsup)."""

from dataclasses import dataclass

import torch

from .batches import WindowBatch
from .contrast_maximisation import average_timestamp_loss
from .losses import bce_dice, charbonnier_smoothness, flow_l1
from .network import NetworkOutput


@dataclass(frozen=True)
class LossWeights:
    future_mask: float = 1.0
    dice: float = 0.5
    # IMOs cover about 1 % of a frame; without extra weight the first hundreds of steps learn
    # "all background" and stay there.
    positive: float = 1.0
    flow: float = 0.1
    smoothness: float = 0.05
    contrast: float = 1.0
    # Below this horizon or event count the future window is too short to show motion blur.
    contrast_min_horizon_ms: float = 10.0
    contrast_min_events: int = 50


def window_objective(
    out: NetworkOutput, batch: WindowBatch, weights: LossWeights, with_contrast: bool = True
) -> dict[str, torch.Tensor]:
    """`with_contrast=False` skips the contrast-maximisation term, which costs on CPU about
    twice the rest of a window's forward and backward pass."""
    valid = batch.mask_valid.view(-1, 1, 1, 1).expand_as(batch.mask)
    current = bce_dice(out.mask_logits, batch.mask, valid, weights.dice, weights.positive)
    future = bce_dice(
        out.future_mask_logits,
        batch.future_mask,
        torch.ones_like(batch.future_mask, dtype=torch.bool),
        weights.dice,
        weights.positive,
    )
    flow = out.future_flow.flatten(0, 1)
    flow_error = flow_l1(flow, batch.future_flow.flatten(0, 1), batch.flow_valid.flatten(0, 1))
    smoothness = charbonnier_smoothness(flow)
    contrast_terms = []
    for sample, events_per_horizon in enumerate(batch.future_events if with_contrast else []):
        for k, events in enumerate(events_per_horizon):
            horizon = float(batch.horizons_ms[sample, k])
            if horizon < weights.contrast_min_horizon_ms or len(events.x) < weights.contrast_min_events:
                continue
            device = out.velocity.device
            contrast_terms.append(
                average_timestamp_loss(
                    torch.from_numpy(events.x).to(device),
                    torch.from_numpy(events.y).to(device),
                    torch.from_numpy(events.t_ms).to(device),
                    torch.from_numpy(events.on).to(device),
                    out.velocity[sample, k],
                    horizon,
                )
            )
    contrast = torch.stack(contrast_terms).mean() if contrast_terms else flow.new_zeros(())
    total = (
        current
        + weights.future_mask * future
        + weights.flow * flow_error
        + weights.smoothness * smoothness
        + weights.contrast * contrast
    )
    with torch.no_grad():
        predicted, truth = out.mask_logits > 0, batch.mask > 0.5
        union = (predicted | truth).sum()
        iou = (predicted & truth).sum() / union if union > 0 else union.new_ones((), dtype=torch.float32)
    return {
        "total": total,
        "mask_iou": iou,
        "mask": current,
        "future_mask": future,
        "flow_l1": flow_error,
        "smoothness": smoothness,
        "contrast": contrast,
    }
