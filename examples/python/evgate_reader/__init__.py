"""Reads the events of an evgate pipeline straight from shared memory as NumPy arrays.

    from evgate_reader import EventReader

    with EventReader(domain="evgate", camera="cam0", stream="kept") as reader:
        for batch in reader.batches():
            events = batch.events          # structured array, fields t, x, y, p
            print(batch.header.t_end_us, events["x"].mean())

Each batch's `events` is a read-only NumPy structured array laid over the iceoryx2 sample's
shared memory: no copy and no per-event Python loop. It is valid until the loop takes the next
batch, which hands the sample back to the publisher; call `events.copy()` to keep it longer.

The record layouts must match crates/evgate-core (`Event`) and crates/evgate-ipc
(`BatchHeader`); the node uses evgate's own iceoryx2 settings, without which no evgate service
is found.
"""

from __future__ import annotations

import ctypes
import os
import stat
import time
from dataclasses import dataclass
from typing import Iterator

import iceoryx2 as iox2
import numpy as np

__all__ = [
    "EVENT_DTYPE",
    "END_OF_STREAM",
    "GAP_DETECTED",
    "STREAM_RESTARTED",
    "Batch",
    "BatchHeader",
    "Event",
    "EventReader",
    "evgate_iceoryx_config",
]

#: crates/evgate-core/src/event.rs `Event` (16 bytes): time in µs, pixel, polarity (1 ON).
EVENT_DTYPE = np.dtype(
    {
        "names": ["t", "x", "y", "p"],
        "formats": ["<i8", "<u2", "<u2", "u1"],
        "offsets": [0, 8, 10, 12],
        "itemsize": 16,
    }
)

#: `BatchHeader.flags` bits (crates/evgate-ipc/src/batch.rs `BatchFlags`).
END_OF_STREAM = 1 << 0
GAP_DETECTED = 1 << 1
STREAM_RESTARTED = 1 << 2

#: The streams of events a gate publishes.
EVENT_STREAMS = ("kept", "suppressed", "events")


class Event(ctypes.Structure):
    """The element type the services declare (`evgate::Event/v1`); read through EVENT_DTYPE."""

    _fields_ = [
        ("t", ctypes.c_int64),
        ("x", ctypes.c_uint16),
        ("y", ctypes.c_uint16),
        ("polarity", ctypes.c_uint8),
        ("reserved", ctypes.c_uint8 * 3),
    ]

    @staticmethod
    def type_name() -> str:
        return "evgate::Event/v1"


class BatchHeader(ctypes.Structure):
    """crates/evgate-ipc/src/batch.rs `BatchHeader`: 64 bytes, 8-byte aligned."""

    _fields_ = [
        ("stream_id", ctypes.c_uint64),
        ("sequence", ctypes.c_uint64),
        ("first_event_index", ctypes.c_uint64),
        ("event_count", ctypes.c_uint64),
        ("t_begin_us", ctypes.c_int64),
        ("t_end_us", ctypes.c_int64),
        ("published_at_monotonic_ns", ctypes.c_uint64),
        ("width", ctypes.c_uint16),
        ("height", ctypes.c_uint16),
        ("flags", ctypes.c_uint32),
    ]

    @staticmethod
    def type_name() -> str:
        return "evgate::BatchHeader/v1"


assert ctypes.sizeof(Event) == EVENT_DTYPE.itemsize == 16 and ctypes.alignment(Event) == 8
assert ctypes.sizeof(BatchHeader) == 64 and ctypes.alignment(BatchHeader) == 8


@dataclass
class Batch:
    """One published batch: a copy of its header and a view of its events."""

    header: BatchHeader
    events: np.ndarray

    @property
    def end_of_stream(self) -> bool:
        return bool(self.header.flags & END_OF_STREAM)

    @property
    def after_gap(self) -> bool:
        return bool(self.header.flags & GAP_DETECTED)


def evgate_iceoryx_config():
    """evgate's iceoryx2 settings (crates/evgate-ipc/src/iceoryx_config.rs): the per-user root
    `$XDG_RUNTIME_DIR/evgate` (else `/tmp/evgate-<uid>`) and the file prefix `evgate<uid>_`.
    Whoever starts first creates the root, mode 0700; it must be this user's and closed to
    others, or the pipeline behind it may be another user's."""
    uid = os.geteuid()
    runtime = os.environ.get("XDG_RUNTIME_DIR", "")
    root = os.path.join(runtime, "evgate") if os.path.isabs(runtime) else f"/tmp/evgate-{uid}"
    try:
        os.mkdir(root, 0o700)
    except FileExistsError:
        pass
    info = os.lstat(root)
    if not stat.S_ISDIR(info.st_mode) or info.st_uid != uid or info.st_mode & 0o077:
        raise PermissionError(
            f"refusing the iceoryx2 root {root}: it must be a directory of user {uid} with mode 0700 "
            f"(found owner {info.st_uid}, mode {stat.S_IMODE(info.st_mode):04o})"
        )
    written = os.path.join(root, "iceoryx2.toml")
    if os.path.isfile(written):
        # The services wrote their configuration there; making it the process-wide one keeps
        # iceoryx2 from looking for config files where it takes none (dead-node cleanup).
        return iox2.config.setup_global_config_from_file(iox2.FilePath.new(written))
    config = iox2.config.default()
    config.global_cfg.root_path = iox2.Path.new(root + "/")
    config.global_cfg.prefix = iox2.FileName.new(f"evgate{uid}_")
    return config


def _open_with_retry(open_service, what: str, deadline: float):
    """The gate creates its services when it starts; wait for them instead of failing."""
    while True:
        try:
            return open_service()
        except Exception as error:  # the bindings raise one exception type per failure kind
            if time.monotonic() >= deadline:
                raise TimeoutError(f"cannot open {what}: {error!r}") from error
            time.sleep(0.05)


def events_view(address: int, count: int) -> np.ndarray:
    """A read-only structured array over `count` events at `address` (no copy)."""
    if count == 0:
        return np.empty(0, dtype=EVENT_DTYPE)
    buffer = (ctypes.c_char * (count * EVENT_DTYPE.itemsize)).from_address(address)
    view = np.frombuffer(buffer, dtype=EVENT_DTYPE, count=count)
    view.flags.writeable = False
    return view


class EventReader:
    """Subscribes to `<domain>/<camera>/<stream>` (kept, suppressed or events) and yields its
    batches; waits up to `open_timeout_s` for the services to appear."""

    def __init__(self, domain: str = "evgate", camera: str = "cam0", stream: str = "kept",
                 open_timeout_s: float = 10.0):
        if stream not in EVENT_STREAMS:
            raise ValueError(f"stream {stream!r}: expected one of {', '.join(EVENT_STREAMS)}")
        iox2.set_log_level_from_env_or(iox2.LogLevel.Warn)
        self._node = iox2.NodeBuilder.new().config(evgate_iceoryx_config()).create(iox2.ServiceType.Ipc)
        name = iox2.ServiceName.new(f"{domain}/{camera}/{stream}")
        what = f"{domain}/{camera}/{stream}"
        deadline = time.monotonic() + open_timeout_s
        service = _open_with_retry(
            lambda: self._node.service_builder(name)
            .publish_subscribe(iox2.Slice[Event])
            .user_header(BatchHeader)
            .open(),
            f"publish-subscribe service {what}",
            deadline,
        )
        self._subscriber = service.subscriber_builder().create()
        wakeups = _open_with_retry(
            lambda: self._node.service_builder(name).event().open(),
            f"event service {what}",
            deadline,
        )
        self._listener = wakeups.listener_builder().create()
        self._pending = None

    def __enter__(self) -> "EventReader":
        return self

    def __exit__(self, *exc) -> None:
        self._release()

    def _release(self) -> None:
        if self._pending is not None:
            self._pending.delete()
            self._pending = None

    def receive(self) -> Batch | None:
        """The next batch if one is waiting, else None; releases the previous one."""
        self._release()
        sample = self._subscriber.receive()
        if sample is None:
            return None
        # The 0.10.0 bindings report the slice's length in bytes (`Slice.len()`); the sample
        # header holds the element count.
        count = sample.header.number_of_elements
        header = BatchHeader.from_buffer_copy(sample.user_header().contents)
        self._pending = sample
        return Batch(header=header, events=events_view(sample.payload().as_ptr(), count))

    def batches(self, idle_timeout_s: float = 10.0) -> Iterator[Batch]:
        """Yields batches as they arrive, sleeping until the gate notifies; stops after the
        end-of-stream batch or `idle_timeout_s` without any."""
        last_batch_at = time.monotonic()
        while True:
            batch = self.receive()
            if batch is None:
                if time.monotonic() - last_batch_at > idle_timeout_s:
                    return
                self._listener.timed_wait(iox2.Duration.from_millis(100))
                continue
            last_batch_at = time.monotonic()
            yield batch
            if batch.end_of_stream:
                self._release()
                return
