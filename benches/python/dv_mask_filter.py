"""dv-processing's EventMaskFilter on the input of benches/gating.rs: 1 M events evenly spaced
over 50 ms, pixels and polarities uniform on a 346x260 sensor, a mask with 20 % of its pixels
set at random (same distributions, NumPy's generator instead of ChaCha8). Times accept() plus
generateEvents() (the filter's whole job on a batch) and prints JSON: M events/s, median and
every run.

    python benches/python/dv_mask_filter.py [--runs 20]

Needs `pip install dv-processing==2.0.4 numpy` (not a project dependency; scripts/bench-gating.sh
runs it when such a Python is given).
"""

import argparse
import json
import statistics
import sys
import time

import numpy as np

EVENTS = 1_000_000
WINDOW_US = 50_000
WIDTH, HEIGHT = 346, 260


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=20, help="timed runs after two warm-up runs")
    args = parser.parse_args()
    import dv_processing as dv

    rng = np.random.default_rng(11)
    structured = np.zeros(
        EVENTS, dtype=[("timestamp", "<i8"), ("x", "<i2"), ("y", "<i2"), ("polarity", "u1")]
    )
    structured["timestamp"] = np.arange(EVENTS, dtype=np.int64) * WINDOW_US // EVENTS
    structured["x"] = rng.integers(0, WIDTH, EVENTS)
    structured["y"] = rng.integers(0, HEIGHT, EVENTS)
    structured["polarity"] = rng.integers(0, 2, EVENTS)
    store = dv.EventStore()
    for t, x, y, p in structured:
        store.push_back(int(t), int(x), int(y), bool(p))
    mask = (rng.random((HEIGHT, WIDTH)) < 0.2).astype(np.uint8) * 255
    seconds = []
    kept = 0
    for run in range(args.runs + 2):
        mask_filter = dv.EventMaskFilter(mask)
        started = time.perf_counter()
        mask_filter.accept(store)
        kept = mask_filter.generateEvents().size()
        elapsed = time.perf_counter() - started
        if run >= 2:
            seconds.append(elapsed)
    median = statistics.median(seconds)
    print(
        json.dumps(
            {
                "bench": "dv-processing EventMaskFilter",
                "dv-processing": getattr(dv, "__version__", "2.0.4"),
                "events": EVENTS,
                "kept": kept,
                "median-s": median,
                "m-events-per-s": EVENTS / median / 1e6,
                "runs-s": seconds,
            },
            indent=2,
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
