"""Training batches drawn by worker processes, so a GPU step does not wait for numpy cropping,
augmentation and voxel look-ups on one CPU core."""

from collections.abc import Iterator

import numpy as np
from torch.utils.data import DataLoader, IterableDataset, get_worker_info

from .batches import ChunkSampler, WindowBatch


class _ChunkStream(IterableDataset):
    def __init__(self, sampler: ChunkSampler, batch: int, seed: int):
        self.sampler = sampler
        self.batch = batch
        self.seed = seed

    def __iter__(self) -> Iterator[list[WindowBatch]]:
        worker = get_worker_info()
        if worker is not None:
            # Each forked worker holds a copy of the sampler: without its own stream every
            # worker would draw the same chunks.
            self.sampler.rng = np.random.default_rng([self.seed, worker.id])
        while True:
            yield self.sampler.sample(self.batch)


def _as_drawn(batches: list[WindowBatch]) -> list[WindowBatch]:
    """The loader's default conversion would turn the future events' numpy arrays into tensors."""
    return batches


def chunk_batches(sampler: ChunkSampler, batch: int, workers: int, seed: int) -> Iterator[list[WindowBatch]]:
    """An endless stream of `sampler.sample(batch)`: in this process when `workers` is 0, else
    from `workers` forked processes (the loaded sequences are shared copy-on-write)."""
    if workers == 0:
        while True:
            yield sampler.sample(batch)
    loader = DataLoader(
        _ChunkStream(sampler, batch, seed),
        batch_size=None,
        collate_fn=_as_drawn,
        num_workers=workers,
        prefetch_factor=4,
        persistent_workers=True,
        multiprocessing_context="fork",
    )
    yield from loader
