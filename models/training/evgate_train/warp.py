"""Backward warping: the value at x after the motion is the value at x - flow(x) before it."""

import numpy as np
import torch
import torch.nn.functional as F


def backward_warp(image: torch.Tensor, flow: torch.Tensor) -> torch.Tensor:
    """Samples `image` [N, C, H, W] at x - flow(x), bilinear, zeros outside the image.

    `flow` [N, 2, H, W] holds (dx, dy) in pixels. Pixel centres sit at integer coordinates
    (align_corners), the same convention as evgate-core's warping.
    """
    _, _, height, width = image.shape
    rows = torch.arange(height, dtype=flow.dtype, device=flow.device).view(1, height, 1)
    cols = torch.arange(width, dtype=flow.dtype, device=flow.device).view(1, 1, width)
    source_x = cols - flow[:, 0]
    source_y = rows - flow[:, 1]
    grid = torch.stack(
        [2.0 * source_x / max(width - 1, 1) - 1.0, 2.0 * source_y / max(height - 1, 1) - 1.0],
        dim=-1,
    )
    return F.grid_sample(image, grid, mode="bilinear", padding_mode="zeros", align_corners=True)


def normalising_scale(height: int, width: int) -> torch.Tensor:
    """[1, 2, 1, 1]: multiplies a flow [N, 2, H, W] in pixels into grid_sample's normalised units
    (align_corners off, where the image spans [-1, 1] over `width` x `height` pixels)."""
    return torch.tensor([2.0 / width, 2.0 / height]).view(1, 2, 1, 1)


def backward_warp_normalised(image: torch.Tensor, normalised_flow: torch.Tensor) -> torch.Tensor:
    """`backward_warp` for a flow already multiplied by `normalising_scale`, with the sampling
    positions normalised the other way (align_corners off): the same positions and values.

    ONNX Runtime's CPU GridSample has a fast path only for bilinear, zero padding and
    align_corners off. The pixel grid is built with numpy so that an ONNX export holds it as a
    constant, and a flow scaled before it is upsampled (upsampling is linear) leaves a
    transpose and a subtraction per warp. Training keeps `backward_warp` so its numerics do not
    change.
    """
    height, width = int(image.shape[2]), int(image.shape[3])
    rows, cols = np.meshgrid(np.arange(height), np.arange(width), indexing="ij")
    # Pixel centre x sits at (2x + 1) / width - 1 when corners are not aligned.
    positions = np.stack([(2 * cols + 1) / width - 1, (2 * rows + 1) / height - 1], axis=-1)
    pixel_grid = torch.from_numpy(positions[None].astype(np.float32))
    if normalised_flow.device.type != "cpu":
        # A trace-time branch: the export (on CPU) keeps the grid a plain constant.
        pixel_grid = pixel_grid.to(normalised_flow.device)
    grid = pixel_grid - normalised_flow.permute(0, 2, 3, 1)
    return F.grid_sample(image, grid, mode="bilinear", padding_mode="zeros", align_corners=False)
