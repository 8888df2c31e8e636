"""Random training chunks: B sequences x L consecutive windows, one crop and one augmentation
per chunk, collated into tensors window by window."""

import dataclasses
from dataclasses import dataclass

import numpy as np
import torch

from .augment import Augmentation, apply
from .sequence import Sequence
from .windows import Crop, FutureEvents, reference_voxel, training_window


class ChunkSamplingError(ValueError):
    """A chunk/crop request that no sequence can satisfy."""


@dataclass
class WindowBatch:
    voxel: torch.Tensor  # [B, 2, S, S]
    mask: torch.Tensor  # [B, 1, S, S]
    mask_valid: torch.Tensor  # [B] bool
    horizons_ms: torch.Tensor  # [B, K]
    future_mask: torch.Tensor  # [B, K, S, S]
    future_flow: torch.Tensor  # [B, K, 2, S, S]
    flow_valid: torch.Tensor  # [B, K, S, S]
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


def collate(windows: list) -> WindowBatch:
    def stack(name: str) -> torch.Tensor:
        return torch.from_numpy(np.stack([getattr(w, name) for w in windows]))

    return WindowBatch(
        voxel=stack("voxel"),
        mask=stack("mask").unsqueeze(1),
        mask_valid=torch.tensor([w.mask_valid for w in windows]),
        horizons_ms=stack("horizons_ms"),
        future_mask=stack("future_mask"),
        future_flow=stack("future_flow"),
        flow_valid=stack("flow_valid"),
        future_events=[w.future_events for w in windows],
        host_horizons_ms=np.stack([w.horizons_ms for w in windows]),
    )


class ChunkSampler:
    def __init__(
        self,
        sequences: list[Sequence],
        chunk_windows: int,
        crop_size: int,
        max_events: int,
        augment: bool,
        seed: int,
        object_crop_share: float = 0.8,
        flow_at_arrival: bool = False,
    ):
        self.sequences = [
            s for s in sequences if len(s.ref_ts) >= chunk_windows and min(s.width, s.height) >= crop_size
        ]
        if not self.sequences:
            raise ChunkSamplingError(
                f"no sequence has {chunk_windows} reference windows and a {crop_size}x{crop_size} crop "
                f"(of {len(sequences)} sequences)"
            )
        self.chunk_windows = chunk_windows
        self.crop_size = crop_size
        self.max_events = max_events
        self.augment = augment
        self.object_crop_share = object_crop_share
        self.flow_at_arrival = flow_at_arrival
        self.rng = np.random.default_rng(seed)
        # Full-frame voxel grids by (sequence, reference): the same windows recur across
        # thousands of steps, and rebuilding a grid from events costs more than a step's forward pass.
        self.voxels: dict[tuple[int, int], np.ndarray] = {}

    def _voxel(self, sequence_index: int, reference: int) -> np.ndarray:
        key = (sequence_index, reference)
        if key not in self.voxels:
            self.voxels[key] = reference_voxel(self.sequences[sequence_index], reference)
        return self.voxels[key]

    def _chunk(self) -> list:
        index = int(self.rng.integers(len(self.sequences)))
        sequence = self.sequences[index]
        start = int(self.rng.integers(len(sequence.ref_ts) - self.chunk_windows + 1))
        crop = self._crop(sequence, start)
        augmentation = Augmentation.draw(self.rng) if self.augment else Augmentation(False, False, False)
        return [
            apply(
                training_window(
                    sequence,
                    start + i,
                    crop,
                    self.max_events,
                    self.rng,
                    self._voxel(index, start + i),
                    self.flow_at_arrival,
                ),
                augmentation,
                self.crop_size,
            )
            for i in range(self.chunk_windows)
        ]

    def _crop(self, sequence: Sequence, start: int) -> Crop:
        """A uniform crop, or with probability `object_crop_share` one that holds a random
        object pixel of the chunk's first window: objects cover about 1 % of an EVIMO-like
        frame, and crops without any teach only the background."""
        left_range = sequence.width - self.crop_size + 1
        top_range = sequence.height - self.crop_size + 1
        frame = sequence.grid_index(int(sequence.ref_ts[start]))
        if frame is not None and self.rng.random() < self.object_crop_share:
            rows, cols = np.nonzero(sequence.masks[frame])
            if rows.size:
                pick = int(self.rng.integers(rows.size))
                low_left = max(0, cols[pick] - self.crop_size + 1)
                low_top = max(0, rows[pick] - self.crop_size + 1)
                return Crop(
                    left=int(self.rng.integers(low_left, min(cols[pick], left_range - 1) + 1)),
                    top=int(self.rng.integers(low_top, min(rows[pick], top_range - 1) + 1)),
                    size=self.crop_size,
                )
        return Crop(
            left=int(self.rng.integers(left_range)),
            top=int(self.rng.integers(top_range)),
            size=self.crop_size,
        )

    def sample(self, batch: int) -> list[WindowBatch]:
        """L window batches, in time order."""
        chunks = [self._chunk() for _ in range(batch)]
        return [collate([chunk[i] for chunk in chunks]) for i in range(self.chunk_windows)]
