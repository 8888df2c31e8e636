#!/usr/bin/env python3
"""Reads the events an evgate gate keeps, straight from shared memory, as NumPy arrays.

Subscribes to `<domain>/<camera>/kept` with `evgate_reader.EventReader` (this folder's package:
`pip install examples/python`, or examples/python/setup.sh), and reads every batch in place: a
NumPy structured array (fields t, x, y, p) laid over the shared-memory slice, with no per-event
Python loop. Prints one JSON object with what it received when it stops: at the end-of-stream
batch, after --max-batches batches, or after --timeout-s seconds without any batch.
"""

import argparse
import json
import sys

from evgate_reader import EventReader


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--domain", default="evgate", help="pipeline domain (first part of the service names)")
    parser.add_argument("--camera", default="cam0", help="camera name (second part of the service names)")
    parser.add_argument("--stream", default="kept", help="kept, suppressed or events")
    parser.add_argument("--max-batches", type=int, default=0, help="stop after this many batches (0: no limit)")
    parser.add_argument("--timeout-s", type=float, default=10.0, help="stop after this long without a batch")
    args = parser.parse_args()

    batches = events = on_events = gaps = 0
    first_t = last_t = None
    ended_by = "timeout"
    with EventReader(args.domain, args.camera, args.stream, open_timeout_s=args.timeout_s) as reader:
        print("ready", file=sys.stderr, flush=True)
        for batch in reader.batches(idle_timeout_s=args.timeout_s):
            view = batch.events
            on_events += int(view["p"].sum(dtype="u8"))
            if len(view):
                first_t = int(view["t"][0]) if first_t is None else first_t
                last_t = int(view["t"][-1])
            batches += 1
            events += len(view)
            gaps += batch.after_gap
            if batch.end_of_stream:
                ended_by = "end-of-stream"
                break
            if args.max_batches and batches >= args.max_batches:
                ended_by = "max-batches"
                break

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
