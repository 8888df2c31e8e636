"""How the network rescales its voxel input before the first convolution, inside the graph so
the exported model carries it and the Rust voxel grid stays the same for every model.

"global": the voxel grid as given (standardised over its non-zero cells, `voxel.normalise`), so
a cell's magnitude depends on how many cells the whole window activates: a dense texture
shrinks every edge.

"local": each cell is divided by the root-mean-square of the active cells (either bin non-zero)
in the LOCAL_WINDOW x LOCAL_WINDOW neighbourhood around it. Counting only active cells makes the
rescaled magnitude independent of how densely the texture fires; both bins of a pixel share the
divisor, so the ratio between them (when in the window its events fell, the motion cue) is kept.
No weights: a network can switch between the two and keep every parameter.
"""

import torch
import torch.nn.functional as F

INPUT_NORMALISATIONS = ("global", "local")
LOCAL_WINDOW = 15
# Below the energy of any active cell of a standardised grid: only guards empty neighbourhoods.
ENERGY_FLOOR = 1e-6


class InputNormalisationError(ValueError):
    """An input normalisation that is not one of `INPUT_NORMALISATIONS`."""


def check_input_normalisation(name: str) -> str:
    if name not in INPUT_NORMALISATIONS:
        raise InputNormalisationError(
            f"unknown input normalisation {name!r}; accepted: {', '.join(INPUT_NORMALISATIONS)}"
        )
    return name


def normalise_input(voxel: torch.Tensor, name: str) -> torch.Tensor:
    """voxel [B, bins, H, W] -> the same shape, rescaled as `name` says."""
    if name == "global":
        return voxel
    energy = (voxel * voxel).sum(dim=1, keepdim=True)
    active = (energy > 0).to(voxel.dtype)
    # Both sums divide by the same window area, so their ratio is the mean over active cells.
    local_energy = box_mean(energy) / (box_mean(active) + ENERGY_FLOOR)
    return voxel * torch.rsqrt(local_energy + ENERGY_FLOOR)


def box_mean(image: torch.Tensor) -> torch.Tensor:
    """Mean over the LOCAL_WINDOW-square around each pixel, zeros outside the image; as two 1-D
    passes (2 K additions per pixel instead of K^2, the same sums)."""
    half = LOCAL_WINDOW // 2
    rows = F.avg_pool2d(image, (1, LOCAL_WINDOW), stride=1, padding=(0, half), count_include_pad=True)
    return F.avg_pool2d(rows, (LOCAL_WINDOW, 1), stride=1, padding=(half, 0), count_include_pad=True)
