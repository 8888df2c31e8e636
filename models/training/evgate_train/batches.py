"""One training step's windows of every stream, collated into tensors."""

import dataclasses
from dataclasses import dataclass

import numpy as np
import torch

from .windows import FutureEvents, TrainingWindow


@dataclass
class WindowBatch:
    voxel: torch.Tensor  # [B, 2, H, W]
    mask: torch.Tensor  # [B, 1, H, W]
    mask_valid: torch.Tensor  # [B] bool
    fired: torch.Tensor  # [B, 1, H, W] bool
    horizons_ms: torch.Tensor  # [B, K]
    future_mask: torch.Tensor  # [B, K, H, W]
    future_valid: torch.Tensor  # [B, K] bool
    future_fired: torch.Tensor  # [B, K, H, W] bool
    footprint: torch.Tensor  # [B, K, H, W] bool
    future_flow: torch.Tensor  # [B, K, 2, H, W]
    flow_valid: torch.Tensor  # [B, K, H, W] bool
    object_region: torch.Tensor  # [B, K, H, W] bool
    future_events: list[list[FutureEvents]]  # [B][K]
    # The horizons stay readable on the host after `to`: the objective decides from them which
    # pairs enter contrast maximisation without waiting for the device.
    host_horizons_ms: np.ndarray  # [B, K] float32

    def to(self, device: torch.device | str) -> "WindowBatch":
        """The tensors on `device`; the future events stay numpy arrays (the objective
        concatenates the qualifying ones and moves them at once)."""
        return dataclasses.replace(
            self,
            **{
                field.name: getattr(self, field.name).to(device, non_blocking=True)
                for field in dataclasses.fields(self)
                if isinstance(getattr(self, field.name), torch.Tensor)
            },
        )


def collate(windows: list[TrainingWindow]) -> WindowBatch:
    def stack(name: str) -> torch.Tensor:
        return torch.from_numpy(np.stack([getattr(w, name) for w in windows]))

    return WindowBatch(
        voxel=stack("voxel"),
        mask=stack("mask").unsqueeze(1),
        mask_valid=torch.tensor([w.mask_valid for w in windows]),
        fired=stack("fired").unsqueeze(1),
        horizons_ms=stack("horizons_ms"),
        future_mask=stack("future_mask"),
        future_valid=stack("future_valid"),
        future_fired=stack("future_fired"),
        footprint=stack("footprint"),
        future_flow=stack("future_flow"),
        flow_valid=stack("flow_valid"),
        object_region=stack("object_region"),
        future_events=[w.future_events for w in windows],
        host_horizons_ms=np.stack([w.horizons_ms for w in windows]),
    )


def concatenated(batches: list[WindowBatch]) -> WindowBatch:
    """The batches' windows as one batch, in order."""
    joined = {}
    for field in dataclasses.fields(WindowBatch):
        values = [getattr(batch, field.name) for batch in batches]
        if isinstance(values[0], torch.Tensor):
            joined[field.name] = torch.cat(values)
        elif isinstance(values[0], np.ndarray):
            joined[field.name] = np.concatenate(values)
        else:
            joined[field.name] = [item for value in values for item in value]
    return WindowBatch(**joined)
