"""Upsampling of the flow decoder's coarse flow to the mask decoder's resolution.

"bilinear" interpolates the coarse flow, so an object smaller than a few coarse cells moves
with a blend of its own and the background's velocity, and no trailing edge can be drawn.
"convex" (mask-guided convex upsampling, after RAFT) lets every fine pixel choose a convex
combination of the 3x3 coarse cells around its own, with weights predicted from the mask
decoder's last features, which know where the object's boundary runs. It is added as a
correction to the bilinear flow, scaled by a per-pixel gate: both heads start at zero, so the
gate is closed and a trained network that gains the convex path computes exactly what it
computed before, at any resolution the bilinear flow is taken.
"""

import torch
import torch.nn.functional as F
from torch import nn

from .decoder import upsample

FLOW_UPSAMPLINGS = ("bilinear", "convex")
NEIGHBOURS = 9


class FlowUpsamplingError(ValueError):
    """A flow upsampling that is not one of `FLOW_UPSAMPLINGS`."""


def check_flow_upsampling(name: str) -> str:
    if name not in FLOW_UPSAMPLINGS:
        raise FlowUpsamplingError(f"unknown flow upsampling {name!r}; accepted: {', '.join(FLOW_UPSAMPLINGS)}")
    return name


def neighbourhoods(coarse: torch.Tensor, factor: int) -> torch.Tensor:
    """[N, 9, C, h * factor, w * factor]: for each fine pixel, the 3x3 coarse cells around the
    one it lies in (row-major), the image's edge cells repeated beyond it as bilinear
    interpolation clamps there."""
    count, channels, height, width = coarse.shape
    padded = F.pad(coarse, (1, 1, 1, 1), mode="replicate")
    shifted = torch.stack(
        [padded[:, :, row : row + height, col : col + width] for row in range(3) for col in range(3)], dim=1
    )
    fine = F.interpolate(shifted.reshape(count, NEIGHBOURS * channels, height, width), scale_factor=float(factor))
    return fine.reshape(count, NEIGHBOURS, channels, height * factor, width * factor)


class ConvexUpsampling(nn.Module):
    def __init__(self, feature_channels: int, factor: int):
        super().__init__()
        self.factor = factor
        self.weight_logits = nn.Conv2d(feature_channels, NEIGHBOURS, 1)
        self.gate = nn.Conv2d(feature_channels, 1, 1)
        for head in (self.weight_logits, self.gate):
            nn.init.zeros_(head.weight)
            nn.init.zeros_(head.bias)

    def guidance(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """From features [B, C, H, W] at the fine resolution: the convex weights [B, 9, 1, H, W]
        (summing to 1 over the neighbours) and the gate [B, 1, H, W]; computed once per window and
        shared by every horizon."""
        return torch.softmax(self.weight_logits(features), dim=1).unsqueeze(2), self.gate(features)

    def forward(self, coarse: torch.Tensor, weights: torch.Tensor, gate: torch.Tensor) -> torch.Tensor:
        """The correction [N, C, h * factor, w * factor] that, added to the bilinear upsampling of
        coarse [N, C, h, w] by `factor`, gives gate * convex + (1 - gate) * bilinear; weights and
        gate from `guidance`, with N rows or one broadcast over all. Linear in `coarse`, so a flow
        may be scaled before or after."""
        convex = (weights * neighbourhoods(coarse, self.factor)).sum(dim=1)
        return gate * (convex - upsample(coarse, self.factor))
