"""Backward warping: the value at x after the motion is the value at x - flow(x) before it."""

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
