"""The suppression network: a recurrent ConvGRU U-Net that predicts the IMO mask now and, for
each requested horizon, a flow that backward-warps the mask logits into the future."""

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from .convgru import ConvGRU
from .decoder import Decoder, upsample
from .sizes import STAGES, base_channels, stage_channels
from .time_conditioning import TimeConditioning, check_variant
from .warp import backward_warp

VOXEL_BINS = 2
INPUT_MULTIPLE = 2**STAGES


class InputSizeError(ValueError):
    """A voxel grid whose height or width is not a multiple of 16."""


@dataclass(frozen=True)
class NetworkConfig:
    size: str = "S"
    time_conditioning: str = "position-aware"
    attention_heads: int = 4
    residual_blocks: int = 2

    @property
    def base(self) -> int:
        return base_channels(self.size)

    @property
    def state_channels(self) -> list[int]:
        return stage_channels(self.base)


@dataclass
class NetworkOutput:
    mask_logits: torch.Tensor  # [B, 1, H, W]
    future_mask_logits: torch.Tensor  # [B, K, H, W]
    future_flow: torch.Tensor  # [B, K, 2, H, W], pixels over each horizon
    velocity: torch.Tensor  # [B, K, 2, H, W], px/ms
    states: list[torch.Tensor]


class ResidualBlock(nn.Module):
    def __init__(self, channels: int):
        super().__init__()
        self.first = nn.Conv2d(channels, channels, 3, padding=1)
        self.second = nn.Conv2d(channels, channels, 3, padding=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(x + self.second(F.relu(self.first(x))))


class SuppressionNetwork(nn.Module):
    def __init__(self, config: NetworkConfig):
        super().__init__()
        check_variant(config.time_conditioning)
        self.config = config
        channels = config.state_channels
        self.downsamples = nn.ModuleList()
        self.recurrent = nn.ModuleList()
        previous = VOXEL_BINS
        for width in channels:
            self.downsamples.append(nn.Conv2d(previous, width, 3, stride=2, padding=1))
            self.recurrent.append(ConvGRU(width, width))
            previous = width
        self.residual = nn.Sequential(*[ResidualBlock(channels[-1]) for _ in range(config.residual_blocks)])
        self.time_conditioning = TimeConditioning(channels[-1], config.time_conditioning, config.attention_heads)
        shallow_to_deep = channels[:-1][::-1]
        # The full-resolution mask level is half as wide: it dominates the cost at large inputs.
        self.mask_decoder = Decoder(channels[-1], shallow_to_deep + [max(channels[0] // 2, 4)], 1)
        # Flow runs once per horizon, so it stops at half resolution and is upsampled bilinearly:
        # flow is smooth and this keeps K horizons cheap.
        self.flow_decoder = Decoder(channels[-1], shallow_to_deep, 2)

    def initial_states(self, batch: int, height: int, width: int) -> list[torch.Tensor]:
        check_input_size(height, width)
        return [
            torch.zeros(batch, c, height >> (stage + 1), width >> (stage + 1))
            for stage, c in enumerate(self.config.state_channels)
        ]

    def forward(self, voxel: torch.Tensor, horizons_ms: torch.Tensor, states: list[torch.Tensor]) -> NetworkOutput:
        """voxel [B, 2, H, W], horizons_ms [B, K], states as `initial_states`."""
        batch, _, height, width = voxel.shape
        horizons = horizons_ms.shape[1]
        x = voxel
        new_states = []
        for downsample, recurrent, state in zip(self.downsamples, self.recurrent, states):
            x = recurrent(F.relu(downsample(x)), state)
            new_states.append(x)
        bottleneck = self.residual(x)
        skips = new_states[:-1][::-1]
        mask_logits = self.mask_decoder(bottleneck, skips)

        def per_horizon(t: torch.Tensor) -> torch.Tensor:
            return t.unsqueeze(1).expand(-1, horizons, *t.shape[1:]).reshape(batch * horizons, *t.shape[1:])

        flat_horizons = horizons_ms.reshape(batch * horizons)
        conditioned = self.time_conditioning(per_horizon(bottleneck), flat_horizons)
        velocity = upsample(self.flow_decoder(conditioned, [per_horizon(s) for s in skips]))
        flow = velocity * flat_horizons.view(-1, 1, 1, 1)
        future = backward_warp(per_horizon(mask_logits), flow)
        return NetworkOutput(
            mask_logits=mask_logits,
            future_mask_logits=future.reshape(batch, horizons, height, width),
            future_flow=flow.reshape(batch, horizons, 2, height, width),
            velocity=velocity.reshape(batch, horizons, 2, height, width),
            states=new_states,
        )


def check_input_size(height: int, width: int) -> None:
    if height % INPUT_MULTIPLE or width % INPUT_MULTIPLE or height <= 0 or width <= 0:
        raise InputSizeError(
            f"voxel grid size {width}x{height} (width x height) is not a positive multiple of {INPUT_MULTIPLE}; "
            "pad right/bottom with zeros"
        )


def parameter_count(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
