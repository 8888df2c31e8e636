"""The convolutional GRU cell that carries each encoder stage's state across windows."""

import torch
from torch import nn


def gate_convolution(input_channels: int, output_channels: int, spatial: bool) -> nn.Module:
    """A 1x1 convolution, or with `spatial` a depthwise 3x3 followed by a 1x1: a full 3x3 gate
    convolution costs 9x more multiply-adds per pixel, which dominates the CPU budget."""
    if not spatial:
        return nn.Conv2d(input_channels, output_channels, 1)
    return nn.Sequential(
        nn.Conv2d(input_channels, input_channels, 3, padding=1, groups=input_channels, bias=False),
        nn.Conv2d(input_channels, output_channels, 1),
    )


class ConvGRU(nn.Module):
    def __init__(self, input_channels: int, hidden_channels: int, spatial: bool = True):
        super().__init__()
        stacked = input_channels + hidden_channels
        # Reset and update gates share one convolution: one pass over the stacked input.
        self.gates = gate_convolution(stacked, 2 * hidden_channels, spatial)
        self.candidate = gate_convolution(stacked, hidden_channels, spatial)

    def forward(self, inputs: torch.Tensor, hidden: torch.Tensor) -> torch.Tensor:
        reset, update = torch.sigmoid(self.gates(torch.cat([inputs, hidden], dim=1))).chunk(2, dim=1)
        candidate = torch.tanh(self.candidate(torch.cat([inputs, reset * hidden], dim=1)))
        return hidden + update * (candidate - hidden)
