"""CPU latency of an exported model through ONNX Runtime (the runtime's execution path).

    python -m evgate_train.latency --model ../evgate-S.onnx --threads 2 --horizons 1,2,5 --output runs/latency.json

Random normalised-voxel-like inputs (fresh each run so nothing is cached), zero states at the
start then the returned states fed back, as a stream does. Reports median, p90 and mean per K.
"""

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import onnx
import onnxruntime
from tqdm import tqdm

from .timings import print_and_save, timing_summary


def measure(session: onnxruntime.InferenceSession, shapes: dict, horizons: int, runs: int, warmup: int) -> dict:
    rng = np.random.default_rng(0)
    states = {name: np.zeros(shape, np.float32) for name, shape in shapes.items() if name.startswith("state_")}
    horizon_values = np.linspace(100.0 / horizons, 100.0, horizons).astype(np.float32)
    timings = []
    for run in tqdm(range(warmup + runs), desc=f"K={horizons}", unit="run", leave=False):
        voxel = np.where(rng.random(shapes["voxel"]) < 0.1, rng.standard_normal(shapes["voxel"]), 0.0).astype(np.float32)
        feeds = {"voxel": voxel, "horizons_ms": horizon_values, **states}
        started = time.perf_counter()
        outputs = session.run(None, feeds)
        elapsed = time.perf_counter() - started
        states = {f"state_{i}": outputs[3 + i] for i in range(4)}
        if run >= warmup:
            timings.append(elapsed * 1000.0)
    return {"horizons": horizons, **timing_summary(timings)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", type=Path, required=True, help="exported .onnx file")
    parser.add_argument("--threads", type=int, default=2, help="ONNX Runtime intra-op threads")
    parser.add_argument("--horizons", default="1,2,5", help="comma-separated K values to time")
    parser.add_argument("--runs", type=int, default=100, help="timed runs per K")
    parser.add_argument("--warmup", type=int, default=10, help="untimed runs first")
    parser.add_argument("--output", type=Path, help="also write the result as JSON here")
    args = parser.parse_args(argv)
    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = args.threads
    options.inter_op_num_threads = 1
    session = onnxruntime.InferenceSession(str(args.model), options, providers=["CPUExecutionProvider"])
    shapes = {i.name: tuple(d if isinstance(d, int) else 1 for d in i.shape) for i in session.get_inputs()}
    metadata = {p.key: p.value for p in onnx.load(str(args.model), load_external_data=False).metadata_props}
    result = {
        "model": str(args.model),
        "size": metadata.get("evgate.model-size"),
        "input": f"{shapes['voxel'][3]}x{shapes['voxel'][2]}",
        "threads": args.threads,
        "onnxruntime": onnxruntime.__version__,
        "cpu": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "load_average": os.getloadavg(),
        "results": [measure(session, shapes, int(k), args.runs, args.warmup) for k in args.horizons.split(",")],
    }
    print_and_save(result, args.output)
    return 0


if __name__ == "__main__":
    sys.exit(main())
