"""What both latency tools report: the summary of per-window times, printed and saved as JSON."""

import json
from pathlib import Path

import numpy as np


def timing_summary(timings_ms: list[float]) -> dict:
    values = np.array(timings_ms)
    return {
        "runs": len(timings_ms),
        "median_ms": round(float(np.median(values)), 3),
        "p90_ms": round(float(np.percentile(values, 90)), 3),
        "mean_ms": round(float(values.mean()), 3),
    }


def print_and_save(result: dict, output: Path | None) -> None:
    print(json.dumps(result, indent=2))
    if output:
        output.parent.mkdir(parents=True, exist_ok=True)
        output.write_text(json.dumps(result, indent=2))
