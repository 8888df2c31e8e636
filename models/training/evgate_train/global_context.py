"""Global context for the mask decoder: the bottleneck's mean over the frame, through a small
MLP, scales and shifts every bottleneck feature (FiLM).

An independently moving object is told from the static scene by comparing its motion with the
camera's, and the camera's motion shows over the whole frame, while each bottleneck feature
sees only its convolutions' neighbourhood. The modulation starts at zero, so a trained network
given it computes what it computed until training opens it."""

import torch
import torch.nn.functional as F
from torch import nn

# The MLP's hidden width is the feature width over this (as in squeeze-and-excitation).
REDUCTION = 4


class GlobalContext(nn.Module):
    def __init__(self, channels: int):
        super().__init__()
        self.summary = nn.Linear(channels, max(channels // REDUCTION, 1))
        self.modulation = nn.Linear(self.summary.out_features, 2 * channels)
        nn.init.zeros_(self.modulation.weight)
        nn.init.zeros_(self.modulation.bias)

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        """features [B, C, H, W] -> the same shape."""
        summary = F.relu(self.summary(features.mean(dim=(2, 3))))
        scale, shift = self.modulation(summary).unsqueeze(-1).unsqueeze(-1).chunk(2, dim=1)
        return features * (1.0 + scale) + shift
