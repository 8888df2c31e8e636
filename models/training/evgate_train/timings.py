"""The summary both latency tools report for a list of per-window times."""

import numpy as np


def timing_summary(timings_ms: list[float]) -> dict:
    values = np.array(timings_ms)
    return {
        "runs": len(timings_ms),
        "median_ms": round(float(np.median(values)), 3),
        "p90_ms": round(float(np.percentile(values, 90)), 3),
        "mean_ms": round(float(values.mean()), 3),
    }
