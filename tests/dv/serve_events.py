#!/usr/bin/env python3
"""Serves a known pattern of events over dv-processing's NetworkWriter, for evgate's tests.

Event i has time FIRST_T + 10 i µs, x = 7 i mod width, y = 13 i mod height and polarity ON for
even i. Events --first to --first + --count - 1 go out in --packets packets once a client is
connected; then the server prints a JSON line and exits, which drops every client. It creates
--ready-file once listening.

The process ends with os._exit: dv-processing 2.0.4's NetworkWriter destructor waits for its
I/O thread, which may wait for the interpreter lock to report the dropped client, so a normal
exit with a client connected hangs.
"""

import argparse
import json
import os
import sys
import time

import dv_processing as dv

FIRST_T = 1_700_000_000_000_000


def event(i: int, width: int, height: int):
    return FIRST_T + 10 * i, (7 * i) % width, (13 * i) % height, i % 2 == 0


def wait_for(condition, what: str, timeout_s: float):
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            print(f"serve_events: timed out waiting for {what}", file=sys.stderr, flush=True)
            os._exit(1)
        time.sleep(0.01)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    endpoint = parser.add_mutually_exclusive_group(required=True)
    endpoint.add_argument("--tcp", type=int, help="serve on 127.0.0.1:PORT")
    endpoint.add_argument("--unix", help="serve on this UNIX socket path")
    parser.add_argument("--first", type=int, default=0)
    parser.add_argument("--count", type=int, required=True)
    parser.add_argument("--packets", type=int, default=10)
    parser.add_argument("--width", type=int, default=320)
    parser.add_argument("--height", type=int, default=240)
    parser.add_argument("--ready-file", required=True)
    parser.add_argument("--timeout-s", type=float, default=60.0)
    args = parser.parse_args()

    stream = dv.io.Stream.EventStream(0, "events", "DVXplorer_evgate_test", (args.width, args.height))
    if args.unix:
        if os.path.exists(args.unix):
            os.unlink(args.unix)
        writer = dv.io.NetworkWriter(dv.Path(args.unix), stream)
    else:
        writer = dv.io.NetworkWriter("127.0.0.1", args.tcp, stream)
    open(args.ready_file, "w").close()
    wait_for(lambda: writer.getClientCount() > 0, "a client", args.timeout_s)
    last = args.first + args.count
    per_packet = max(1, -(-args.count // args.packets))
    for start in range(args.first, last, per_packet):
        store = dv.EventStore()
        for i in range(start, min(last, start + per_packet)):
            store.push_back(*event(i, args.width, args.height))
        writer.writeEvents(store)
    wait_for(lambda: writer.getQueuedPacketCount() == 0, "the queue to drain", args.timeout_s)
    # Let the last bytes leave the socket before the process drops it.
    time.sleep(0.3)
    print(json.dumps({"first": args.first, "count": args.count}), flush=True)
    os._exit(0)


if __name__ == "__main__":
    main()
