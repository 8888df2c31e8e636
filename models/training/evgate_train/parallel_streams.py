"""Training streams drawn by worker processes. One core builds about 60 windows a second (voxel
grid, jitter, ground-truth targets); a large batch on a GPU consumes several times that. The
streams are split into `workers` shards, each a `StreamSampler` of its own seed playing its
share of the streams in its own process; a step joins one step of every shard, so batch slot s
is stream s % per_shard of shard s // per_shard. The cursor is every shard's, so a resumed run
continues each shard's data stream."""

import dataclasses
import inspect
import resource

import numpy as np
import torch
from torch.utils.data import DataLoader, IterableDataset, get_worker_info

from .batches import WindowBatch, concatenated
from .streams import StreamSampler, StreamSetupError, StreamStep

# Steps each worker builds ahead of the one being trained on.
STEPS_AHEAD = 2
# File descriptors this process keeps besides the steps in flight.
OTHER_FILES = 1024


def allow_open_files(count: int) -> None:
    """Raises this process's open-file limit to `count` where the hard limit allows: every tensor a
    worker sends holds a file descriptor until it is freed, so the steps in flight of many
    workers pass the usual soft limit of 1024 ("Too many open files")."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft != resource.RLIM_INFINITY and soft < count:
        resource.setrlimit(resource.RLIMIT_NOFILE, (count if hard == resource.RLIM_INFINITY else min(count, hard), hard))


def shard_seed(seed: int, shard: int) -> int:
    return seed + 7919 * shard


class _ShardSteps(IterableDataset):
    """Every worker process plays the shard of its id from the given cursor, endlessly."""

    def __init__(self, sampler_arguments: list[dict], cursors: list[dict]):
        self.sampler_arguments = sampler_arguments
        self.cursors = cursors

    def __iter__(self):
        shard = get_worker_info().id
        torch.set_num_threads(1)
        sampler = StreamSampler(**self.sampler_arguments[shard])
        sampler.load_state_dict(self.cursors[shard])
        while True:
            step = sampler.step()
            yield shard, step, sampler.state_dict()


class ShardedStreams:
    """A `StreamSampler` of `streams` streams (the same step, state_dict, load_state_dict and
    played_voxels) whose steps are built by `workers` processes."""

    def __init__(self, workers: int, *sampler_args, **sampler_kwargs):
        """`workers` processes; the other arguments are `StreamSampler`'s, for all the streams."""
        arguments = inspect.signature(StreamSampler).bind(*sampler_args, **sampler_kwargs).arguments
        streams = arguments["streams"]
        if workers < 1 or streams % workers != 0:
            raise StreamSetupError(
                f"{streams} streams over {workers} data workers: the streams must split evenly between the "
                "workers (a multiple of the worker count)"
            )
        self.workers = workers
        self.streams = streams
        self.windows_per_step = arguments["windows_per_step"]
        self.crop_height, self.crop_width = arguments["crop_height"], arguments["crop_width"]
        self.streams_per_shard = streams // workers
        self.sampler_arguments = [
            {**arguments, "streams": self.streams_per_shard, "seed": shard_seed(arguments["seed"], shard)}
            for shard in range(workers)
        ]
        # In this process the shards only replay what a resumed run played (`played_voxels`);
        # they load their sequences when asked.
        self.shards = [StreamSampler(**arguments) for arguments in self.sampler_arguments]
        self.cursors = [shard.state_dict() for shard in self.shards]
        self._steps = None

    def step(self) -> StreamStep:
        if self._steps is None:
            tensors_per_step = self.windows_per_step * len(dataclasses.fields(WindowBatch))
            allow_open_files(OTHER_FILES + 2 * self.workers * (STEPS_AHEAD + 2) * tensors_per_step)
            loader = DataLoader(
                _ShardSteps(self.sampler_arguments, self.cursors),
                batch_size=None,
                num_workers=self.workers,
                multiprocessing_context="spawn",
                prefetch_factor=STEPS_AHEAD,
                persistent_workers=True,
            )
            self._steps = iter(loader)
        parts = [next(self._steps) for _ in range(self.workers)]
        order = [shard for shard, _, _ in parts]
        if order != list(range(self.workers)):
            raise RuntimeError(f"the data workers answered out of turn: shards {order}")
        self.cursors = [cursor for _, _, cursor in parts]
        steps = [step for _, step, _ in parts]
        return StreamStep(
            [concatenated([step.windows[i] for step in steps]) for i in range(self.windows_per_step)],
            np.concatenate([step.starts for step in steps]),
        )

    def state_dict(self) -> dict:
        """Every shard's cursor after the last step."""
        return {"shards": list(self.cursors)}

    def load_state_dict(self, state: dict) -> None:
        if self._steps is not None:
            raise StreamSetupError("the data cursor can only be set before the first step")
        shards = state.get("shards")
        if shards is None or len(shards) != self.workers:
            found = "one in-process sampler" if shards is None else f"{len(shards)} data workers"
            raise StreamSetupError(
                f"the data cursor was saved by {found}; this run has {self.workers} data workers: resume with "
                "the same --data-workers"
            )
        for shard, cursor in zip(self.shards, shards):
            shard.load_state_dict(cursor)
        self.cursors = list(shards)

    def played_voxels(self, slot: int) -> list[np.ndarray]:
        return self.shards[slot // self.streams_per_shard].played_voxels(slot % self.streams_per_shard)
