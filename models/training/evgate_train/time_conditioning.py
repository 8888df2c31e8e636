"""Attention-based time conditioning (ATC) of the deepest features on the forecast horizon.

The paper's reference code queries the feature tokens with the horizon encoding alone, the
same query at every position, so every position attends identically and the conditioning
adds one spatially constant vector. The position-aware variant adds the horizon encoding to
each position's own (normalised) token, so each position can attend to the tokens that
matter for its own future motion.

Keys and values come from the tokens average-pooled 3x3 with stride 2: the attention's cost
repeats per horizon and grows with the product of query and key counts, and the pooled map
still covers every position.
"""

import math

import torch
import torch.nn.functional as F
from torch import nn

VARIANTS = ("position-aware", "reference", "none")


class UnknownVariantError(ValueError):
    """A time-conditioning variant name that is not accepted."""


def check_variant(variant: str) -> str:
    if variant not in VARIANTS:
        raise UnknownVariantError(f"unknown time-conditioning variant {variant!r}; accepted: {', '.join(VARIANTS)}")
    return variant


def horizon_encoding(horizons_ms: torch.Tensor, dimension: int) -> torch.Tensor:
    """Sinusoidal encoding of continuous horizons [N] (ms) into [N, dimension] (paper, Eq. 9-10)."""
    half = dimension // 2
    exponents = torch.arange(half, dtype=horizons_ms.dtype, device=horizons_ms.device) * (2.0 / dimension)
    frequencies = torch.exp(-math.log(10000.0) * exponents)
    angles = horizons_ms[:, None] * frequencies[None, :]
    # Interleaved sin/cos: index 2k is sin, 2k+1 is cos.
    return torch.stack([torch.sin(angles), torch.cos(angles)], dim=-1).reshape(horizons_ms.shape[0], 2 * half)


class TimeConditioning(nn.Module):
    def __init__(self, channels: int, variant: str, heads: int = 4):
        super().__init__()
        self.variant = check_variant(variant)
        self.channels = channels
        if variant == "none":
            return
        if channels % heads != 0:
            raise ValueError(f"time conditioning: channels {channels} not divisible by heads {heads}")
        self.heads = heads
        self.time_embedding = nn.Sequential(nn.Linear(channels, channels), nn.ReLU(), nn.Linear(channels, channels))
        self.token_norm = nn.LayerNorm(channels)
        self.query = nn.Linear(channels, channels)
        self.key = nn.Linear(channels, channels)
        self.value = nn.Linear(channels, channels)
        self.output = nn.Linear(channels, channels)
        self.feed_forward_norm = nn.LayerNorm(channels)
        self.feed_forward = nn.Sequential(nn.Linear(channels, 2 * channels), nn.ReLU(), nn.Linear(2 * channels, channels))

    def attention_update(self, features: torch.Tensor, horizons_ms: torch.Tensor) -> torch.Tensor:
        """The cross-attention output [N, h*w, C] that is added to the tokens of features [N, C, h, w]."""
        batch = features.shape[0]
        channels = self.channels
        tokens = features.flatten(2).transpose(1, 2)
        normalised = self.token_norm(tokens)
        pooled = F.avg_pool2d(features, 3, stride=2, padding=1, count_include_pad=False)
        pooled_normalised = self.token_norm(pooled.flatten(2).transpose(1, 2))
        time = self.time_embedding(horizon_encoding(horizons_ms, channels))[:, None, :]
        if self.variant == "position-aware":
            query_input = normalised + time
        else:
            query_input = time.expand(-1, tokens.shape[1], -1)
        head_channels = channels // self.heads

        def split_heads(x: torch.Tensor) -> torch.Tensor:
            return x.reshape(batch, -1, self.heads, head_channels).transpose(1, 2)

        query = split_heads(self.query(query_input))
        key = split_heads(self.key(pooled_normalised))
        value = split_heads(self.value(pooled_normalised))
        weights = torch.softmax(query @ key.transpose(-1, -2) / math.sqrt(head_channels), dim=-1)
        attended = (weights @ value).transpose(1, 2).reshape(batch, -1, channels)
        return self.output(attended)

    def forward(self, features: torch.Tensor, horizons_ms: torch.Tensor) -> torch.Tensor:
        """Conditions features [N, C, h, w] on horizons [N] (ms); returns [N, C, h, w]."""
        if self.variant == "none":
            return features
        batch, channels, height, width = features.shape
        tokens = features.flatten(2).transpose(1, 2) + self.attention_update(features, horizons_ms)
        tokens = tokens + self.feed_forward(self.feed_forward_norm(tokens))
        return tokens.transpose(1, 2).reshape(batch, self.channels, height, width)
