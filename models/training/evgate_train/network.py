"""The suppression network: a recurrent ConvGRU U-Net that predicts the IMO mask now and, for
each requested horizon, a flow that backward-warps the mask logits into the future.

Built for a CPU budget of about 1 GFLOP per window at 346x260: the first encoder stage runs at
half resolution (a stride-2 stem), the two shallow ConvGRUs use 1x1 gates and the deep ones
depthwise-separable 3x3 gates, the decoders are narrow (the model's base width; `NetworkConfig`
can move the first 3x3 stage and widen the mask decoder), the mask decoder ends at half
resolution and the flow decoder, run once per horizon, at an eighth; both are upsampled
bilinearly. Training warps the mask logits at full resolution; the exported graph
warps them at half resolution, where the mask decoder ends (`WARP_RESOLUTIONS`)."""

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from .convgru import ConvGRU
from .decoder import Decoder, upsample
from .flow_upsampling import ConvexUpsampling, check_flow_upsampling
from .global_context import GlobalContext
from .input_normalisation import check_input_normalisation, normalise_input
from .sizes import STAGES, base_channels, stage_channels
from .time_conditioning import TimeConditioning, check_variant
from .warp import backward_warp, backward_warp_normalised, normalising_scale

VOXEL_BINS = 2
INPUT_MULTIPLE = 2**STAGES


class InputSizeError(ValueError):
    """A voxel grid whose height or width is not a multiple of 16."""


class ArchitectureError(ValueError):
    """A mask decoder width factor below 1, a first spatial ConvGRU stage outside the encoder or
    an encoder narrower than the size's base width."""


def check_architecture(config: "NetworkConfig") -> None:
    if config.mask_decoder_width_factor < 1:
        raise ArchitectureError(
            f"mask decoder width factor {config.mask_decoder_width_factor}: must be 1 (the base width) or more"
        )
    if not 0 <= config.first_spatial_gru_stage <= STAGES:
        raise ArchitectureError(
            f"first spatial ConvGRU stage {config.first_spatial_gru_stage}: must be 0 to {STAGES} "
            f"({STAGES}: 1x1 gates everywhere)"
        )
    if config.encoder_base_channels is not None and config.encoder_base_channels < config.base:
        raise ArchitectureError(
            f"encoder base channels {config.encoder_base_channels}: must be the size's base width "
            f"({config.base}) or more"
        )


class WarpResolutionError(ValueError):
    """A warp resolution that is not one of `WARP_RESOLUTIONS`."""


# Where the future mask logits are warped. "full": the upsampled logits by the full-resolution
# flow (training, and exports before the half-resolution path). "half": the mask decoder's
# half-resolution logits by the flow upsampled to half resolution, then the K warped maps are
# upsampled; a quarter of the sampling, for the CPU budget of the exported graph.
WARP_RESOLUTIONS = ("full", "half")


def check_warp_resolution(resolution: str) -> str:
    if resolution not in WARP_RESOLUTIONS:
        raise WarpResolutionError(f"unknown warp resolution {resolution!r}; accepted: {', '.join(WARP_RESOLUTIONS)}")
    return resolution


# The default `NetworkConfig.first_spatial_gru_stage`: the shallow, high-resolution stages keep
# 1x1 gates, which the CPU budget was drawn around.
FIRST_SPATIAL_GRU_STAGE = 2
# The flow decoder runs this many levels above the bottleneck (stride 16 -> 8), then its
# velocity is upsampled bilinearly: its cost repeats per horizon.
FLOW_DECODER_LEVELS = 1


@dataclass(frozen=True)
class NetworkConfig:
    size: str = "S"
    time_conditioning: str = "position-aware"
    attention_heads: int = 4
    residual_blocks: int = 2
    input_normalisation: str = "global"
    # Time bins of the voxel grid (`voxel.accumulate`); the runtime builds 2.
    voxel_bins: int = VOXEL_BINS
    # A last input channel: the window's events warped by the fitted ego-motion
    # (`motion_compensation`); the runtime does not build it yet.
    motion_compensated_channel: bool = False
    # How the coarse flow reaches the mask decoder's resolution (`flow_upsampling`).
    flow_upsampling: str = "bilinear"
    # The mask decoder's width in multiples of the base width. It runs once per window, unlike
    # the flow decoder, so widening it buys current-instant capacity without a per-horizon cost.
    mask_decoder_width_factor: int = 1
    # Encoder stages from this index on have 3x3 (depthwise-separable) ConvGRU gates; the
    # shallower ones have 1x1 gates and take their spatial context from the stride-2 convs.
    first_spatial_gru_stage: int = FIRST_SPATIAL_GRU_STAGE
    # The encoder's first-stage width (each stage doubles it); None: the size's base width. The
    # decoders and the attention keep the base width, so the encoder alone grows.
    encoder_base_channels: int | None = None
    # The mask decoder reads the bottleneck modulated by its mean over the frame
    # (`global_context`); the flow decoder has its own global view through the attention.
    global_context: bool = False

    @property
    def input_channels(self) -> int:
        return self.voxel_bins + int(self.motion_compensated_channel)

    @property
    def base(self) -> int:
        return base_channels(self.size)

    @property
    def decoder_width(self) -> int:
        """The flow decoder's width."""
        return self.base

    @property
    def mask_decoder_width(self) -> int:
        return self.base * self.mask_decoder_width_factor

    @property
    def attention_width(self) -> int:
        """ATC runs on the bottleneck projected to this width: its cost repeats per horizon."""
        return 2 * self.base

    @property
    def state_channels(self) -> list[int]:
        return stage_channels(self.encoder_base_channels or self.base)


@dataclass
class NetworkOutput:
    mask_logits: torch.Tensor  # [B, 1, H, W]
    future_mask_logits: torch.Tensor  # [B, K, H, W]
    future_flow: torch.Tensor  # [B, K, 2, H, W], pixels over each horizon
    # [B, K, 2, H / s, W / s] with s = SuppressionNetwork.flow_stride: the same flow at the flow
    # decoder's own resolution, before the upsampling (what an export outputs).
    coarse_flow: torch.Tensor
    velocity: torch.Tensor  # [B, K, 2, H, W], px/ms
    states: list[torch.Tensor]


def separable_convolution(channels: int) -> nn.Module:
    return nn.Sequential(
        nn.Conv2d(channels, channels, 3, padding=1, groups=channels, bias=False), nn.Conv2d(channels, channels, 1)
    )


class ResidualBlock(nn.Module):
    def __init__(self, channels: int):
        super().__init__()
        self.first = separable_convolution(channels)
        self.second = separable_convolution(channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(x + self.second(F.relu(self.first(x))))


class SuppressionNetwork(nn.Module):
    def __init__(self, config: NetworkConfig):
        super().__init__()
        check_variant(config.time_conditioning)
        check_input_normalisation(config.input_normalisation)
        check_flow_upsampling(config.flow_upsampling)
        check_architecture(config)
        self.config = config
        channels = config.state_channels
        self.downsamples = nn.ModuleList()
        self.recurrent = nn.ModuleList()
        previous = config.input_channels
        for stage, width in enumerate(channels):
            # Batch norm speeds up the short CPU training; at export it folds into the conv.
            self.downsamples.append(
                nn.Sequential(nn.Conv2d(previous, width, 3, stride=2, padding=1), nn.BatchNorm2d(width))
            )
            self.recurrent.append(ConvGRU(width, width, spatial=stage >= config.first_spatial_gru_stage))
            previous = width
        self.residual = nn.Sequential(*[ResidualBlock(channels[-1]) for _ in range(config.residual_blocks)])
        skip_channels = channels[:-1][::-1]
        # Ends at the first stage's resolution (half the input); logits are upsampled from there.
        self.mask_decoder = Decoder(channels[-1], config.mask_decoder_width, skip_channels, 1)
        self.global_context = GlobalContext(channels[-1]) if config.global_context else None
        self.flow_features = nn.Conv2d(channels[-1], config.attention_width, 1)
        self.time_conditioning = TimeConditioning(
            config.attention_width, config.time_conditioning, config.attention_heads
        )
        # Runs once per horizon, so it stops coarse: flow is smooth and upsampled bilinearly.
        self.flow_decoder = Decoder(
            config.attention_width, config.decoder_width, skip_channels[:FLOW_DECODER_LEVELS], 2
        )
        self.flow_stride = 2 ** (STAGES - FLOW_DECODER_LEVELS)
        # To the mask decoder's (half) resolution, guided by its features.
        self.convex_upsampling = (
            ConvexUpsampling(config.mask_decoder_width, self.flow_stride // 2)
            if config.flow_upsampling == "convex"
            else None
        )

    def upsample_flow(self, coarse: torch.Tensor, correction: torch.Tensor | None, to_full: bool) -> torch.Tensor:
        """Coarse flow [N, 2, H / s, W / s] to half resolution [N, 2, H / 2, W / 2], or with
        `to_full` to [N, 2, H, W]; `correction` is the convex upsampling's (`ConvexUpsampling`, at
        half resolution) for this coarse flow, None for bilinear."""
        flow = upsample(coarse, self.flow_stride if to_full else self.flow_stride // 2)
        if correction is None:
            return flow
        return flow + (upsample(correction) if to_full else correction)

    def mask_decoder_input(self, bottleneck: torch.Tensor) -> torch.Tensor:
        return bottleneck if self.global_context is None else self.global_context(bottleneck)

    def initial_states(
        self, batch: int, height: int, width: int, device: torch.device | str = "cpu"
    ) -> list[torch.Tensor]:
        check_input_size(height, width)
        return [
            torch.zeros(batch, c, height >> (stage + 1), width >> (stage + 1), device=device)
            for stage, c in enumerate(self.config.state_channels)
        ]

    def forward(
        self, voxel: torch.Tensor, horizons_ms: torch.Tensor, states: list[torch.Tensor], warp_resolution: str = "full"
    ) -> NetworkOutput:
        """voxel [B, config.input_channels, H, W] (`network_input`), horizons_ms [B, K], states as
        `initial_states`; `warp_resolution` one of `WARP_RESOLUTIONS` (only the future mask logits
        depend on it)."""
        check_warp_resolution(warp_resolution)
        batch, _, height, width = voxel.shape
        horizons = horizons_ms.shape[1]
        x = normalise_input(voxel, self.config.input_normalisation)
        new_states = []
        for downsample, recurrent, state in zip(self.downsamples, self.recurrent, states):
            x = recurrent(F.relu(downsample(x)), state)
            new_states.append(x)
        bottleneck = self.residual(x)
        skips = new_states[:-1][::-1]
        half_mask_logits, mask_features = self.mask_decoder.forward_with_features(
            self.mask_decoder_input(bottleneck), self.mask_decoder.project_skips(skips)
        )
        mask_logits = upsample(half_mask_logits)

        def per_horizon(t: torch.Tensor) -> torch.Tensor:
            return t.unsqueeze(1).expand(-1, horizons, *t.shape[1:]).reshape(batch * horizons, *t.shape[1:])

        flat_horizons = horizons_ms.reshape(batch * horizons)
        conditioned = self.time_conditioning(per_horizon(self.flow_features(bottleneck)), flat_horizons)
        flow_skips = [per_horizon(s) for s in self.flow_decoder.project_skips(skips[:FLOW_DECODER_LEVELS])]
        coarse_velocity = self.flow_decoder(conditioned, flow_skips)
        # The convex correction is linear in the coarse flow: made once, for the velocity, and
        # scaled like the flow for each use.
        velocity_correction = flow_correction = None
        if self.convex_upsampling is not None:
            guidance = (per_horizon(g) for g in self.convex_upsampling.guidance(mask_features))
            velocity_correction = self.convex_upsampling(coarse_velocity, *guidance)
            flow_correction = velocity_correction * flat_horizons.view(-1, 1, 1, 1)
        velocity = self.upsample_flow(coarse_velocity, velocity_correction, to_full=True)
        # Upsampling is linear, so scaling by the horizon before it gives the same flow with a
        # full-resolution multiply less per horizon.
        coarse_flow = coarse_velocity * flat_horizons.view(-1, 1, 1, 1)
        flow = self.upsample_flow(coarse_flow, flow_correction, to_full=True)
        if warp_resolution == "full":
            future = backward_warp(per_horizon(mask_logits), flow)
        else:
            # Half-resolution pixels are twice as large (the displacement halves); scaling the
            # coarse flow before the (linear) upsampling keeps the multiply off the large map.
            half_height, half_width = half_mask_logits.shape[-2:]
            scale = 0.5 * normalising_scale(half_height, half_width).to(coarse_flow)
            half_correction = None if flow_correction is None else flow_correction * scale
            half_flow = self.upsample_flow(coarse_flow * scale, half_correction, to_full=False)
            future = upsample(backward_warp_normalised(per_horizon(half_mask_logits), half_flow))
        return NetworkOutput(
            mask_logits=mask_logits,
            future_mask_logits=future.reshape(batch, horizons, height, width),
            future_flow=flow.reshape(batch, horizons, 2, height, width),
            coarse_flow=coarse_flow.reshape(batch, horizons, 2, height // self.flow_stride, width // self.flow_stride),
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
