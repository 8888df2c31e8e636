#!/usr/bin/env python3
"""Reads the events an evgate gate keeps, straight from shared memory.

Subscribes to `<domain>/<camera>/kept` (a slice of `evgate::Event/v1` records with an
`evgate::BatchHeader/v1` user header), sleeps on the event service of the same name until the
gate publishes, and reads every batch in place (a ctypes array laid over the shared-memory slice).
Prints one JSON object with what it received when it stops: at the end-of-stream batch,
after --max-batches batches, or after --timeout-s seconds without any batch.

The node uses evgate's own iceoryx2 settings (`evgate_iceoryx_config`), not iceoryx2's defaults:
a consumer on the defaults finds no evgate service.

Setup: examples/python/setup.sh (installs the iceoryx2 bindings of the version the Rust crates
use; the record layouts below must match crates/evgate-ipc and crates/evgate-core).
"""

import argparse
import ctypes
import json
import os
import stat
import sys
import time

import iceoryx2 as iox2


class Event(ctypes.Structure):
    """crates/evgate-core/src/event.rs `Event`: 16 bytes, 8-byte aligned."""

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


END_OF_STREAM = 1 << 0
GAP_DETECTED = 1 << 1

assert ctypes.sizeof(Event) == 16 and ctypes.alignment(Event) == 8
assert ctypes.sizeof(BatchHeader) == 64 and ctypes.alignment(BatchHeader) == 8


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
        raise SystemExit(
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


def open_with_retry(open_service, what: str, deadline: float):
    """The gate creates its services when it starts; wait for them instead of failing."""
    while True:
        try:
            return open_service()
        except Exception as error:  # the bindings raise one exception type per failure kind
            if time.monotonic() >= deadline:
                raise SystemExit(f"cannot open {what}: {error!r}") from error
            time.sleep(0.05)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--domain", default="evgate", help="pipeline domain (first part of the service names)")
    parser.add_argument("--camera", default="cam0", help="camera name (second part of the service names)")
    parser.add_argument("--max-batches", type=int, default=0, help="stop after this many batches (0: no limit)")
    parser.add_argument("--timeout-s", type=float, default=10.0, help="stop after this long without a batch")
    args = parser.parse_args()

    iox2.set_log_level_from_env_or(iox2.LogLevel.Warn)
    node = iox2.NodeBuilder.new().config(evgate_iceoryx_config()).create(iox2.ServiceType.Ipc)
    name = iox2.ServiceName.new(f"{args.domain}/{args.camera}/kept")
    deadline = time.monotonic() + args.timeout_s
    service = open_with_retry(
        lambda: node.service_builder(name)
        .publish_subscribe(iox2.Slice[Event])
        .user_header(BatchHeader)
        .open(),
        f"publish-subscribe service {args.domain}/{args.camera}/kept",
        deadline,
    )
    subscriber = service.subscriber_builder().create()
    wakeups = open_with_retry(
        lambda: node.service_builder(name).event().open(),
        f"event service {args.domain}/{args.camera}/kept",
        deadline,
    )
    listener = wakeups.listener_builder().create()
    print("ready", file=sys.stderr, flush=True)

    batches = events = on_events = gaps = 0
    first_t = last_t = None
    ended_by = "timeout"
    last_batch_at = time.monotonic()
    done = False
    while not done:
        # Sleeps until the gate notifies (or 100 ms pass, to check the timeout).
        listener.timed_wait(iox2.Duration.from_millis(100))
        while True:
            sample = subscriber.receive()
            if sample is None:
                break
            header = sample.user_header().contents
            # The iceoryx2 0.10.0 bindings report the received slice's length in bytes
            # (`Slice.len()`); the sample header holds the element count.
            count = sample.header.number_of_elements
            # A ctypes array laid over the shared memory: no copy of the batch.
            records = (Event * count).from_address(sample.payload().as_ptr())
            for event in records:
                on_events += event.polarity
            if count > 0:
                first_t = records[0].t if first_t is None else first_t
                last_t = records[count - 1].t
            batches += 1
            events += count
            gaps += bool(header.flags & GAP_DETECTED)
            end = bool(header.flags & END_OF_STREAM)
            sample.delete()
            last_batch_at = time.monotonic()
            if end:
                ended_by, done = "end-of-stream", True
                break
            if args.max_batches and batches >= args.max_batches:
                ended_by, done = "max-batches", True
                break
        if not done and time.monotonic() - last_batch_at > args.timeout_s:
            done = True

    print(json.dumps({
        "batches": batches,
        "events": events,
        "on-events": on_events,
        "first-event-time-us": first_t,
        "last-event-time-us": last_t,
        "batches-after-gap": gaps,
        "ended-by": ended_by,
    }))
    return 0


if __name__ == "__main__":
    sys.exit(main())
