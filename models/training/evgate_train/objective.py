"""The training objective of one window: supervised mask and flow terms plus the
unsupervised contrast-maximisation term (paper, appendix: L = w_sup L_sup + w_unsup L_unsup)."""

from dataclasses import dataclass

import numpy as np
import torch

from .batches import WindowBatch
from .contrast_maximisation import batched_average_timestamp_loss
from .losses import bce_dice, charbonnier_smoothness, flow_l1_by_region, small_object_emphasis
from .network import NetworkOutput
from .warp import backward_warp

# The warped true mask is a probability; it is kept this far from 0 and 1 so that its logit,
# which the BCE + Dice loss takes, stays finite.
TRUE_MASK_MARGIN = 0.02


@dataclass(frozen=True)
class LossWeights:
    future_mask: float = 1.0
    dice: float = 0.5
    # IMOs cover about 1 % of a frame; without extra weight the first hundreds of steps learn
    # "all background" and stay there.
    positive: float = 1.0
    flow: float = 0.1
    smoothness: float = 0.05
    # Off by default: in every logged run the term stayed flat (about 0.116) at about 28 % of
    # the step time.
    contrast: float = 0.0
    # Extra BCE weight of the pixels with an event within 5 ms of a mask's time: per-event F1
    # scores the mask only where events arrive, uniform weights spend the loss on silent
    # interiors and background alike.
    fired_pixels: float = 0.0
    # IMO pixels of a true component smaller than this many pixels weigh this area / its area
    # times as much in the mask BCE (`small_object_emphasis`); 0: off.
    small_object_area: float = 0.0
    # The true mask at t warped by the predicted flow against the true mask at t + h: a flow
    # signal that does not depend on how good the predicted current mask is.
    true_mask_warp: float = 0.0
    # The mask BCE's focal exponent (`bce_dice`): 0 is plain BCE. Most pixels are easy
    # background; a focal BCE spends its weight on the hard ones instead (tied in its A/B,
    # model card).
    focal_gamma: float = 0.0
    # Below this horizon or event count the future window is too short to show motion blur.
    contrast_min_horizon_ms: float = 10.0
    contrast_min_events: int = 50


def window_objective(
    out: NetworkOutput, batch: WindowBatch, weights: LossWeights, with_contrast: bool = True
) -> dict[str, torch.Tensor]:
    """`with_contrast=False` skips the contrast-maximisation term (`contrast_term`)."""
    valid = batch.mask_valid.view(-1, 1, 1, 1).expand_as(batch.mask)
    current = bce_dice(
        out.mask_logits,
        batch.mask,
        valid,
        weights.dice,
        weights.positive,
        mask_emphasis(batch.mask, batch.fired, weights),
        weights.focal_gamma,
    )
    future_valid = batch.future_valid[..., None, None].expand_as(batch.future_mask)
    future = bce_dice(
        out.future_mask_logits,
        batch.future_mask,
        future_valid,
        weights.dice,
        weights.positive,
        mask_emphasis(batch.future_mask, batch.future_fired, weights),
        weights.focal_gamma,
    )
    flow = out.future_flow.flatten(0, 1)
    flow_valid = (batch.flow_valid & future_valid).flatten(0, 1)
    region = batch.object_region.flatten(0, 1)
    flow_error = flow_l1_by_region(flow, batch.future_flow.flatten(0, 1), flow_valid, region)
    smoothness = (
        charbonnier_smoothness(flow, batch.footprint.flatten(0, 1), region)
        if weights.smoothness > 0
        else flow.new_zeros(())
    )
    true_mask_warp = (
        true_mask_warp_term(flow, batch, weights) if weights.true_mask_warp > 0 else flow.new_zeros(())
    )
    contrast = (
        contrast_term(out.velocity, batch, weights) if with_contrast and weights.contrast > 0 else flow.new_zeros(())
    )
    total = (
        current
        + weights.future_mask * future
        + weights.flow * flow_error
        + weights.smoothness * smoothness
        + weights.contrast * contrast
        + weights.true_mask_warp * true_mask_warp
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
        "true_mask_warp": true_mask_warp,
    }


def mask_emphasis(target: torch.Tensor, fired: torch.Tensor, weights: LossWeights) -> torch.Tensor | None:
    """The extra BCE weight of each pixel of a mask `target`: its fired-pixel and small-object
    emphases; None when both are off."""
    parts = []
    if weights.fired_pixels > 0:
        parts.append(fired * weights.fired_pixels)
    if weights.small_object_area > 0:
        parts.append(small_object_emphasis(target, weights.small_object_area))
    return sum(parts[1:], parts[0]) if parts else None


def true_mask_warp_term(flow: torch.Tensor, batch: WindowBatch, weights: LossWeights) -> torch.Tensor:
    """BCE + Dice of the true current mask backward-warped by `flow` [B*K, 2, H, W] against the
    true future mask, over the windows whose current mask is known. The mask is warped as a
    probability, so what enters from outside the image is background."""
    horizons = batch.future_mask.shape[1]
    per_horizon = batch.mask.unsqueeze(1).expand(-1, horizons, -1, -1, -1).flatten(0, 1)
    warped = backward_warp(per_horizon, flow).view_as(batch.future_mask)
    warped = torch.logit(TRUE_MASK_MARGIN + (1.0 - 2.0 * TRUE_MASK_MARGIN) * warped)
    valid = (batch.mask_valid.view(-1, 1) & batch.future_valid)[..., None, None].expand_as(batch.future_mask)
    return bce_dice(warped, batch.future_mask, valid, weights.dice, weights.positive)


def contrast_term(velocity: torch.Tensor, batch: WindowBatch, weights: LossWeights) -> torch.Tensor:
    """Mean contrast-maximisation loss over the (sample, horizon) pairs whose horizon and event
    count are long enough; zero without any. Which pairs qualify is decided from the host copies
    of the horizons and events, so the device is never waited on; the events of all qualifying
    pairs travel to the device in one array."""
    samples, horizons = batch.host_horizons_ms.shape
    pairs = [
        (sample, k)
        for sample in range(samples)
        for k in range(horizons)
        if batch.host_horizons_ms[sample, k] >= weights.contrast_min_horizon_ms
        and len(batch.future_events[sample][k].x) >= weights.contrast_min_events
    ]
    if not pairs:
        return velocity.new_zeros(())
    events = [batch.future_events[sample][k] for sample, k in pairs]
    # Rows x, y, t_ms, on, window index: float32 holds the small integers exactly.
    packed = np.concatenate(
        [
            np.stack([e.x, e.y, e.t_ms, e.on, np.full(len(e.x), window)]).astype(np.float32)
            for window, e in enumerate(events)
        ],
        axis=1,
    )
    x, y, t_ms, on, window = _to_device(torch.from_numpy(packed), velocity.device)
    selected = _to_device(torch.tensor([sample * horizons + k for sample, k in pairs]), velocity.device)
    losses = batched_average_timestamp_loss(
        x,
        y,
        t_ms,
        on > 0.5,
        window.long(),
        velocity.flatten(0, 1)[selected],
        batch.horizons_ms.to(velocity.dtype).flatten()[selected],
    )
    return losses.mean()


def _to_device(host: torch.Tensor, device: torch.device) -> torch.Tensor:
    """An asynchronous copy: a blocking one would wait for the forward pass queued before it.
    Only page-locked memory is copied asynchronously to a GPU."""
    if device.type == "cuda":
        host = host.pin_memory()
    return host.to(device, non_blocking=True)
