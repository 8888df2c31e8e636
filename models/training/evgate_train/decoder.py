"""Coarse-to-fine decoder: bilinear x2 upsampling, 3x3 conv, encoder skips summed in, and a
1x1 head at every scale that refines the previous scale's prediction."""

import torch
import torch.nn.functional as F
from torch import nn


def upsample(x: torch.Tensor) -> torch.Tensor:
    return F.interpolate(x, scale_factor=2.0, mode="bilinear", align_corners=False)


class Decoder(nn.Module):
    def __init__(self, bottleneck_channels: int, level_channels: list[int], output_channels: int):
        """`level_channels[i]` is the width after the i-th upsampling (deep to shallow); levels
        that meet an encoder stage of the same resolution must share its width."""
        super().__init__()
        self.output_channels = output_channels
        self.coarse_head = nn.Conv2d(bottleneck_channels, output_channels, 1)
        previous = bottleneck_channels
        self.convs = nn.ModuleList()
        self.heads = nn.ModuleList()
        for channels in level_channels:
            self.convs.append(nn.Conv2d(previous + output_channels, channels, 3, padding=1))
            self.heads.append(nn.Conv2d(channels, output_channels, 1))
            previous = channels
        # Refinements start at zero so the coarse estimate passes through untouched at first.
        for head in self.heads:
            nn.init.zeros_(head.weight)
            nn.init.zeros_(head.bias)

    def forward(self, bottleneck: torch.Tensor, skips: list[torch.Tensor]) -> torch.Tensor:
        """`skips[i]` is summed after the i-th upsampling (deep to shallow); fewer skips than
        levels leave the last levels without one."""
        x = bottleneck
        prediction = self.coarse_head(x)
        for level, (conv, head) in enumerate(zip(self.convs, self.heads)):
            x = upsample(x)
            prediction = upsample(prediction)
            x = F.relu(conv(torch.cat([x, prediction], dim=1)))
            if level < len(skips):
                x = x + skips[level]
            prediction = prediction + head(x)
        return prediction
