"""What the network sees of one 50 ms window: the standardised voxel grid of the network's
`voxel_bins` bins (`voxel`), then, when the network asks for it, the ego-motion-compensated
event image (`motion_compensation`) as one more channel."""

import numpy as np

from .motion_compensation import compensated_image
from .network import NetworkConfig
from .voxel import voxel_grid


def network_input(
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    on: np.ndarray,
    t_end: int,
    width: int,
    height: int,
    config: NetworkConfig,
) -> np.ndarray:
    """[config.input_channels, padded(height), padded(width)] float32 for the window ending at
    t_end (µs)."""
    voxel = voxel_grid(t, x, y, on, t_end, width, height, config.voxel_bins)
    if not config.motion_compensated_channel:
        return voxel
    return np.concatenate([voxel, compensated_image(t, x, y, t_end, width, height)])
