#!/usr/bin/env python3
"""Reads an AEDAT 4 network stream with dv-processing's NetworkReader, for evgate's tests.

Connects to --tcp PORT on 127.0.0.1 or to --unix PATH, reads event batches until the server
closes the stream (or --timeout-s passes), and prints one JSON object: the sensor size, the
event count, the ON count and the sums of t, x and y, which a test compares with what it
published. The NetworkReader constructor returns only once the stream header arrived and holds
the interpreter meanwhile, so a test learns that the connection is up from the server's side.
The server may still be binding its socket when this starts, so a refused connection is retried
until the timeout.
"""

import argparse
import json
import os
import sys
import time

import dv_processing as dv


def connect(args: argparse.Namespace, deadline: float) -> "dv.io.NetworkReader":
    while True:
        try:
            if args.unix:
                return dv.io.NetworkReader(dv.Path(args.unix))
            return dv.io.NetworkReader("127.0.0.1", args.tcp)
        except RuntimeError as error:
            refused = "Connection refused" in str(error) or "No such file" in str(error)
            if not refused or time.monotonic() >= deadline:
                raise
            time.sleep(0.05)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    endpoint = parser.add_mutually_exclusive_group(required=True)
    endpoint.add_argument("--tcp", type=int)
    endpoint.add_argument("--unix")
    parser.add_argument("--timeout-s", type=float, default=60.0)
    args = parser.parse_args()

    deadline = time.monotonic() + args.timeout_s
    reader = connect(args, deadline)
    width, height = reader.getEventResolution()
    events = on = sum_t = sum_x = sum_y = 0
    while reader.isRunning() and time.monotonic() < deadline:
        batch = reader.getNextEventBatch()
        if batch is None:
            time.sleep(0.001)
            continue
        array = batch.numpy()
        events += len(array)
        on += int(array["polarity"].sum())
        sum_t += int(array["timestamp"].astype("int64").sum())
        sum_x += int(array["x"].astype("int64").sum())
        sum_y += int(array["y"].astype("int64").sum())
    print(json.dumps({
        "width": width, "height": height, "events": events, "on-events": on,
        "sum-t": sum_t, "sum-x": sum_x, "sum-y": sum_y,
        "ended-by": "closed" if not reader.isRunning() else "timeout",
    }), flush=True)
    os._exit(0)


if __name__ == "__main__":
    main()
