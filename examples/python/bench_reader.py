#!/usr/bin/env python3
"""Events per second of two ways to read a stream's batches in Python, on the same batches.

For each batch of `<domain>/<camera>/<stream>` it times (1) the per-event loop of a ctypes array
over the slice (how examples/python/kept_consumer.py read events before evgate_reader) and (2)
evgate_reader's NumPy view, each computing the same figures (ON events, first and last time,
sum of x), and checks that they agree. Prints one JSON object at the end of the stream.
"""

import argparse
import ctypes
import json
import sys
import time

from evgate_reader import Event, EventReader


def per_event_loop(address: int, count: int):
    records = (Event * count).from_address(address)
    on = x_sum = 0
    for event in records:
        on += event.polarity
        x_sum += event.x
    return on, x_sum, (records[0].t, records[count - 1].t) if count else None


def numpy_view(view):
    on = int(view["p"].sum(dtype="u8"))
    x_sum = int(view["x"].sum(dtype="u8"))
    return on, x_sum, (int(view["t"][0]), int(view["t"][-1])) if len(view) else None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--domain", default="evgate")
    parser.add_argument("--camera", default="cam0")
    parser.add_argument("--stream", default="kept", help="kept, suppressed or events")
    parser.add_argument("--timeout-s", type=float, default=10.0, help="stop after this long without a batch")
    args = parser.parse_args()

    loop_s = numpy_s = 0.0
    batches = events = 0
    with EventReader(args.domain, args.camera, args.stream, open_timeout_s=args.timeout_s) as reader:
        print("ready", file=sys.stderr, flush=True)
        for batch in reader.batches(idle_timeout_s=args.timeout_s):
            view = batch.events
            address = view.__array_interface__["data"][0]
            started = time.perf_counter()
            by_loop = per_event_loop(address, len(view))
            loop_s += time.perf_counter() - started
            started = time.perf_counter()
            by_numpy = numpy_view(view)
            numpy_s += time.perf_counter() - started
            if by_loop != by_numpy:
                raise SystemExit(f"batch {batches}: the loop read {by_loop}, NumPy {by_numpy}")
            batches += 1
            events += len(view)

    print(json.dumps({
        "batches": batches,
        "events": events,
        "per-event-loop-events-per-s": events / loop_s if loop_s else None,
        "numpy-view-events-per-s": events / numpy_s if numpy_s else None,
        "speed-up": loop_s / numpy_s if numpy_s else None,
    }))
    return 0


if __name__ == "__main__":
    sys.exit(main())
