"""The exported computation: `SuppressionNetwork.forward` for one stream and K horizons, with
the work that does not depend on the horizon done once instead of on K copies.

Training runs the network on K copies of the bottleneck, skips and mask logits, one per
horizon (its batch is B x K). An export has one stream, so the copies are the same tensor:
here the time conditioning is factorised (`factorised_attention`), the flow decoder adds its
projected skip by broadcasting, and the half-resolution warp samples the one logit map with
the K sampling grids stacked along the grid's height, so no copy of the map is made. Same
weights, same outputs up to float rounding (the export's parity test compares this graph
with `SuppressionNetwork.forward`).
"""

import numpy as np
import torch
import torch.nn.functional as F

from .decoder import upsample
from .export_gru import gru_step
from .factorised_attention import condition_horizons
from .input_normalisation import normalise_input
from .network import FLOW_DECODER_LEVELS, SuppressionNetwork, check_warp_resolution
from .warp import backward_warp, normalising_scale


def pixel_centres(height: int, width: int) -> torch.Tensor:
    """[height, width, 2]: each pixel centre's (x, y) in grid_sample's units with align_corners
    off, as `warp.backward_warp_normalised` builds them; a constant in the exported graph."""
    rows, cols = np.meshgrid(np.arange(height), np.arange(width), indexing="ij")
    positions = np.stack([(2 * cols + 1) / width - 1, (2 * rows + 1) / height - 1], axis=-1)
    return torch.from_numpy(positions.astype(np.float32))


def export_forward(
    network: SuppressionNetwork, voxel: torch.Tensor, horizons_ms: torch.Tensor, states: list[torch.Tensor],
    warp_resolution: str,
) -> tuple[torch.Tensor, ...]:
    """voxel [1, 2, H, W], horizons_ms [K]; returns (mask logits [1, 1, H, W], future mask
    logits [1, K, H, W], coarse flow [1, K, 2, H / s, W / s], new states), as docs/model-contract.md."""
    check_warp_resolution(warp_resolution)
    _, _, height, width = voxel.shape
    horizons = horizons_ms.shape[0]
    x = normalise_input(voxel, network.config.input_normalisation)
    new_states = []
    for downsample, recurrent, state in zip(network.downsamples, network.recurrent, states):
        x = gru_step(recurrent, torch.relu(downsample(x)), state)
        new_states.append(x)
    bottleneck = network.residual(x)
    skips = new_states[:-1][::-1]
    half_mask_logits, mask_features = network.mask_decoder.forward_with_features(
        network.mask_decoder_input(bottleneck), network.mask_decoder.project_skips(skips)
    )
    # The (shape-preserving) reshape keeps ONNX Runtime from upsampling the one logit channel in
    # its blocked layout, where it is padded to a block of 8 channels: 8x the work.
    mask_logits = upsample(half_mask_logits.reshape(1, 1, height // 2, width // 2))

    conditioned = condition_horizons(network.time_conditioning, network.flow_features(bottleneck), horizons_ms)
    # The projected skips stay [1, ...]: the decoder adds them to its [K, ...] features.
    flow_skips = network.flow_decoder.project_skips(skips[:FLOW_DECODER_LEVELS])
    coarse_velocity = network.flow_decoder(conditioned, flow_skips)
    coarse_flow = coarse_velocity * horizons_ms.view(-1, 1, 1, 1)
    stride = network.flow_stride
    # One window: the convex upsampling's guidance [1, ...] broadcasts over the K horizons.
    guidance = None if network.convex_upsampling is None else network.convex_upsampling.guidance(mask_features)

    def upsample_flow(coarse: torch.Tensor, to_full: bool) -> torch.Tensor:
        correction = None if guidance is None else network.convex_upsampling(coarse, *guidance)
        return network.upsample_flow(coarse, correction, to_full)

    if warp_resolution == "full":
        flow = upsample_flow(coarse_flow, to_full=True)
        future = backward_warp(mask_logits.expand(horizons, -1, -1, -1), flow).reshape(1, horizons, height, width)
    else:
        half_height, half_width = half_mask_logits.shape[-2:]
        scale = 0.5 * normalising_scale(half_height, half_width).to(coarse_flow)
        half_flow = upsample_flow(coarse_flow * scale, to_full=False)  # [K, 2, H / 2, W / 2]
        grid = pixel_centres(half_height, half_width) - half_flow.permute(0, 2, 3, 1)
        # One map per horizon (a copy): ONNX Runtime's GridSample reuses its per-image sampling
        # plan buffer across the batch, and one stacked K-times-taller grid measured slower.
        warped = F.grid_sample(
            half_mask_logits.expand(horizons, -1, -1, -1), grid,
            mode="bilinear", padding_mode="zeros", align_corners=False,
        )
        future = upsample(warped.reshape(1, horizons, half_height, half_width))
    return (
        mask_logits,
        future,
        coarse_flow.reshape(1, horizons, 2, height // stride, width // stride),
        *new_states,
    )
