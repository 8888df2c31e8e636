"""Coarse-to-fine decoder: a 1x1 reduction to the decoder's width, then per level bilinear x2
upsampling, a 3x3 conv over features and the current prediction, a 1x1-projected encoder skip
summed in, and a 1x1 head that refines the previous scale's prediction."""

import torch
import torch.nn.functional as F
from torch import nn


def upsample(x: torch.Tensor, factor: int = 2) -> torch.Tensor:
    return F.interpolate(x, scale_factor=float(factor), mode="bilinear", align_corners=False)


class Decoder(nn.Module):
    def __init__(self, input_channels: int, width: int, skip_channels: list[int], output_channels: int):
        """One level per entry of `skip_channels` (deep to shallow), each at twice the
        resolution of the previous one. A narrow `width` keeps the high-resolution levels cheap."""
        super().__init__()
        self.reduce = nn.Conv2d(input_channels, width, 1)
        self.coarse_head = nn.Conv2d(width, output_channels, 1)
        self.skip_projections = nn.ModuleList(nn.Conv2d(channels, width, 1) for channels in skip_channels)
        self.convs = nn.ModuleList(
            nn.Sequential(nn.Conv2d(width + output_channels, width, 3, padding=1), nn.BatchNorm2d(width))
            for _ in skip_channels
        )
        self.heads = nn.ModuleList(nn.Conv2d(width, output_channels, 1) for _ in skip_channels)
        # Refinements start at zero so the coarse estimate passes through untouched at first.
        for head in self.heads:
            nn.init.zeros_(head.weight)
            nn.init.zeros_(head.bias)

    def project_skips(self, skips: list[torch.Tensor]) -> list[torch.Tensor]:
        """Separate from `forward` so that a decoder run once per horizon projects its skips once."""
        return [projection(skip) for projection, skip in zip(self.skip_projections, skips)]

    def forward(self, features: torch.Tensor, projected_skips: list[torch.Tensor]) -> torch.Tensor:
        return self.forward_with_features(features, projected_skips)[0]

    def forward_with_features(
        self, features: torch.Tensor, projected_skips: list[torch.Tensor]
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The prediction and the last level's features, which can guide another output."""
        x = F.relu(self.reduce(features))
        prediction = self.coarse_head(x)
        for conv, head, skip in zip(self.convs, self.heads, projected_skips):
            x = upsample(x)
            prediction = upsample(prediction)
            x = F.relu(conv(torch.cat([x, prediction], dim=1)) + skip)
            prediction = prediction + head(x)
        return prediction, x
