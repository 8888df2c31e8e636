"""Training streams: each batch slot plays one sequence from (near) its start to its end, a
fixed crop and augmentation throughout, `windows_per_step` consecutive windows per step, so the
recurrent state can be carried across steps as the runtime carries it across a recording.

Sequences are taken in shuffled passes over the data, loaded by a background thread ahead of
use and dropped when no stream needs them: a full suite does not fit in memory. The cursor
(random state, pass order, every stream's place) is part of the checkpoint, so a resumed run
continues the same data stream."""

from collections import OrderedDict
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from .augment import Augmentation, apply, augmented_voxel
from .batches import WindowBatch, collate
from .jitter import EventJitter, JitterRanges
from .sequence import Sequence, load_sequence
from .voxel import padded
from .network import NetworkConfig
from .windows import Crop, cropped, draw_horizons, reference_input, training_window

# Sequences loaded ahead of the streams that will need them.
PREFETCHED_SEQUENCES = 2


class StreamSetupError(ValueError):
    """Streams that cannot be formed: no sequences, or a bad step length or cursor."""


@dataclass
class StreamCursor:
    sequence: int  # index into the sampler's paths
    crop: Crop
    augmentation: Augmentation
    first_reference: int
    next_reference: int


@dataclass
class StreamStep:
    windows: list[WindowBatch]  # windows_per_step batches, in time order
    # [streams] bool: the stream of this slot starts here, so its recurrent state is zero.
    starts: np.ndarray


def preset_of(path: Path) -> str:
    """The preset of a suite sequence, from its folder `<preset>-<seed>`."""
    return path.parent.name.rsplit("-", 1)[0]


class StreamSampler:
    def __init__(
        self,
        paths: list[Path],
        streams: int,
        windows_per_step: int,
        crop_height: int,
        crop_width: int,
        horizons: int,
        max_events: int,
        augment: bool,
        seed: int,
        jitter: JitterRanges | None = None,
        network: NetworkConfig = NetworkConfig(),
    ):
        if not paths:
            raise StreamSetupError("no training sequences")
        if streams < 1 or windows_per_step < 1:
            raise StreamSetupError(f"streams {streams} and windows per step {windows_per_step}: both must be 1 or more")
        self.paths = list(paths)
        self.streams = streams
        self.windows_per_step = windows_per_step
        self.crop_height, self.crop_width = crop_height, crop_width
        self.horizons = horizons
        draw_horizons(np.random.default_rng(0), horizons)  # rejects a bad count before any loading
        self.max_events = max_events
        self.augment = augment
        self.rng = np.random.default_rng(seed)
        # Jitter draws from its own generator, so a run with jitter plays the same sequences,
        # crops and horizons as one without: the two can be compared pair by pair.
        self.jitter = jitter
        self.jitter_rng = np.random.default_rng([seed, 1])
        # The input channels the network takes (`network_input`).
        self.network = network
        self.order: list[int] = []
        self.position = 0
        self.passes = 0
        self.cursors: list[StreamCursor | None] = [None] * streams
        self.loaded: OrderedDict[int, Future] = OrderedDict()
        self.pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="sequence-loader")

    def _upcoming(self, count: int) -> list[int]:
        """The next `count` sequences of the pass order, drawing new passes as needed."""
        while len(self.order) - self.position < count:
            self.order = self.order[self.position :] + [int(i) for i in self.rng.permutation(len(self.paths))]
            self.position = 0
            self.passes += 1
        return self.order[self.position : self.position + count]

    def _request(self, index: int) -> Future:
        if index not in self.loaded:
            self.loaded[index] = self.pool.submit(load_sequence, self.paths[index])
        return self.loaded[index]

    def _sequence(self, index: int) -> Sequence:
        return self._request(index).result()

    def _start(self) -> StreamCursor:
        index = self._upcoming(1)[0]
        self.position += 1
        sequence = self._sequence(index)
        for upcoming in self._upcoming(PREFETCHED_SEQUENCES):
            self._request(upcoming)
        top_range = max(0, padded(sequence.height) - self.crop_height)
        left_range = max(0, padded(sequence.width) - self.crop_width)
        crop = Crop(
            left=int(self.rng.integers(left_range + 1)),
            top=int(self.rng.integers(top_range + 1)),
            height=self.crop_height,
            width=self.crop_width,
        )
        augmentation = Augmentation.draw(self.rng) if self.augment else Augmentation.none()
        if self.jitter is not None:
            augmentation = replace(augmentation, jitter=EventJitter.draw(self.jitter_rng, self.jitter))
        # Streams start a few windows apart so that the slots do not all restart on one step.
        first = int(self.rng.integers(self.windows_per_step))
        return StreamCursor(index, crop, augmentation, first, first)

    def _ended(self, cursor: StreamCursor | None) -> bool:
        if cursor is None:
            return True
        references = len(self._sequence(cursor.sequence).ref_ts)
        return cursor.next_reference + self.windows_per_step > references

    def _forget_unused(self) -> None:
        needed = {c.sequence for c in self.cursors if c is not None}
        needed.update(self.order[self.position : self.position + PREFETCHED_SEQUENCES])
        for index in [i for i in self.loaded if i not in needed]:
            del self.loaded[index]

    def step(self) -> StreamStep:
        starts = np.zeros(self.streams, bool)
        for slot, cursor in enumerate(self.cursors):
            if self._ended(cursor):
                self.cursors[slot] = self._start()
                starts[slot] = True
        self._forget_unused()
        per_stream = [self._windows(cursor) for cursor in self.cursors]
        return StreamStep([collate([w[i] for w in per_stream]) for i in range(self.windows_per_step)], starts)

    def _windows(self, cursor: StreamCursor) -> list:
        sequence = self._sequence(cursor.sequence)
        windows = []
        for reference in range(cursor.next_reference, cursor.next_reference + self.windows_per_step):
            window = training_window(
                sequence,
                reference,
                cursor.crop,
                draw_horizons(self.rng, self.horizons),
                reference_input(sequence, reference, cursor.augmentation.jitter, self.network),
                self.max_events,
                self.rng,
            )
            windows.append(apply(window, cursor.augmentation, self.network.voxel_bins))
        cursor.next_reference += self.windows_per_step
        return windows

    def played_voxels(self, slot: int) -> list[np.ndarray]:
        """The augmented voxel grids a stream has played so far, in order: a resumed run
        replays them to rebuild the stream's recurrent state instead of storing it."""
        cursor = self.cursors[slot]
        if cursor is None:
            return []
        sequence = self._sequence(cursor.sequence)
        return [
            augmented_voxel(
                cropped(reference_input(sequence, reference, cursor.augmentation.jitter, self.network), cursor.crop),
                cursor.augmentation,
                self.network.voxel_bins,
            )
            for reference in range(cursor.first_reference, cursor.next_reference)
        ]

    def state_dict(self) -> dict:
        """The data cursor: enough to continue the same stream of windows after a restart."""
        return {
            "paths": [str(p) for p in self.paths],
            "rng": self.rng.bit_generator.state,
            "jitter-rng": self.jitter_rng.bit_generator.state,
            "order": list(self.order),
            "position": self.position,
            "passes": self.passes,
            "cursors": [asdict(c) if c is not None else None for c in self.cursors],
        }

    def load_state_dict(self, state: dict) -> None:
        if "shards" in state:
            raise StreamSetupError(
                f"the data cursor was saved by {len(state['shards'])} data workers; this run draws its windows "
                "in-process: resume with the same --data-workers"
            )
        if state["paths"] != [str(p) for p in self.paths]:
            raise StreamSetupError(
                f"the data cursor was saved over {len(state['paths'])} sequences that differ from the "
                f"{len(self.paths)} found now; resume on the same --data"
            )
        if len(state["cursors"]) != self.streams:
            raise StreamSetupError(f"the data cursor has {len(state['cursors'])} streams, this run {self.streams}")
        self.rng.bit_generator.state = state["rng"]
        if "jitter-rng" in state:
            self.jitter_rng.bit_generator.state = state["jitter-rng"]
        self.order, self.position, self.passes = list(state["order"]), int(state["position"]), int(state["passes"])
        self.cursors = [
            StreamCursor(
                c["sequence"],
                Crop(**c["crop"]),
                Augmentation.from_dict(c["augmentation"]),
                c["first_reference"],
                c["next_reference"],
            )
            if c is not None
            else None
            for c in state["cursors"]
        ]
        self.loaded.clear()
