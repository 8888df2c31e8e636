"""Where the time of an exported model goes: ONNX Runtime's own profiler, per operator.

    python -m evgate_train.profile_operators --model ../evgate-S.onnx --threads 2 --horizons 8,1 \
        --output ../../evidence/models/latency/profile-S.json

Runs the model as a stream does (zero states, then the returned states fed back) with the
session options of the Rust runtime (graph optimisation level all, memory pattern off, one
inter-op thread), and sums the profiler's node events per operator type and per node over
the timed runs. Prints the top entries per K and writes everything as JSON.
"""

import argparse
import json
import os
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

import numpy as np
import onnxruntime
from tqdm import tqdm


class ProfileError(ValueError):
    """A horizon count that is not a positive integer, or a profile the runtime did not write."""


def parse_horizon_counts(text: str) -> list[int]:
    counts = []
    for item in text.split(","):
        if not item.strip().isdigit() or int(item) < 1:
            raise ProfileError(f"--horizons {text!r}: {item!r} is not a positive integer horizon count")
        counts.append(int(item))
    return counts


def session_options(threads: int, profile_prefix: str) -> onnxruntime.SessionOptions:
    """The Rust runtime's settings (crates/evgate-model/src/runtime.rs), plus the profiler."""
    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1
    options.graph_optimization_level = onnxruntime.GraphOptimizationLevel.ORT_ENABLE_ALL
    options.enable_mem_pattern = False
    options.add_session_config_entry("session.intra_op.allow_spinning", "0")
    options.enable_profiling = True
    options.profile_file_prefix = profile_prefix
    return options


def run_stream(session: onnxruntime.InferenceSession, horizons: int, runs: int, warmup: int) -> None:
    shapes = {i.name: tuple(i.shape) for i in session.get_inputs() if i.name != "horizons_ms"}
    rng = np.random.default_rng(0)
    states = {name: np.zeros(shape, np.float32) for name, shape in shapes.items() if name.startswith("state_")}
    horizon_values = np.linspace(100.0 / horizons, 100.0, horizons).astype(np.float32)
    for _ in tqdm(range(warmup + runs), desc=f"K={horizons}", unit="run", leave=False):
        voxel = np.where(rng.random(shapes["voxel"]) < 0.1, rng.standard_normal(shapes["voxel"]), 0.0)
        outputs = session.run(None, {"voxel": voxel.astype(np.float32), "horizons_ms": horizon_values, **states})
        states = {f"state_{i}": outputs[3 + i] for i in range(4)}


def summarise(trace: list[dict], warmup: int, runs: int, top: int) -> dict:
    """Sums node durations of the timed runs (the profiler numbers runs by `model_run` events)."""
    model_runs = sorted((e for e in trace if e.get("name") == "model_run"), key=lambda e: e["ts"])
    if len(model_runs) != warmup + runs:
        raise ProfileError(f"profile holds {len(model_runs)} model_run events, expected {warmup + runs}")
    timed = model_runs[warmup:]
    first_timed = timed[0]["ts"]
    per_type: dict[str, float] = defaultdict(float)
    per_node: dict[str, float] = defaultdict(float)
    node_type: dict[str, str] = {}
    for event in trace:
        if event.get("cat") != "Node" or not event.get("name", "").endswith("_kernel_time"):
            continue
        if event["ts"] < first_timed:
            continue
        op = event["args"]["op_name"]
        node = event["name"].removesuffix("_kernel_time")
        per_type[op] += event["dur"]
        per_node[node] += event["dur"]
        node_type[node] = op
    run_ms = sorted(e["dur"] / 1000.0 for e in timed)
    kernel_total_ms = sum(per_type.values()) / 1000.0 / runs

    def per_run(table: dict[str, float]) -> list[tuple[str, float]]:
        return sorted(((name, us / 1000.0 / runs) for name, us in table.items()), key=lambda item: -item[1])

    return {
        "runs": runs,
        "run_median_ms": round(float(np.median(run_ms)), 3),
        "run_min_ms": round(run_ms[0], 3),
        "kernel_ms_per_run": round(kernel_total_ms, 3),
        "per_operator_type": [
            {"op": op, "ms_per_run": round(ms, 3), "share": round(ms / kernel_total_ms, 4)} for op, ms in per_run(per_type)
        ],
        "top_nodes": [
            {"node": node, "op": node_type[node], "ms_per_run": round(ms, 3)} for node, ms in per_run(per_node)[:top]
        ],
    }


def profile(model: Path, threads: int, horizons: int, runs: int, warmup: int, top: int) -> dict:
    with tempfile.TemporaryDirectory() as directory:
        options = session_options(threads, str(Path(directory) / "ort-profile"))
        session = onnxruntime.InferenceSession(str(model), options, providers=["CPUExecutionProvider"])
        run_stream(session, horizons, runs, warmup)
        trace_path = Path(session.end_profiling())
        trace = json.loads(trace_path.read_text())
    return {"horizons": horizons, **summarise(trace, warmup, runs, top)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", type=Path, required=True, help="exported .onnx file")
    parser.add_argument("--threads", type=int, default=2, help="ONNX Runtime intra-op threads")
    parser.add_argument("--horizons", default="8,1", help="comma-separated horizon counts K to profile")
    parser.add_argument("--runs", type=int, default=30, help="profiled runs per K")
    parser.add_argument("--warmup", type=int, default=5, help="runs first, left out of the sums")
    parser.add_argument("--top", type=int, default=15, help="nodes listed per K")
    parser.add_argument("--output", type=Path, help="also write the result as JSON here")
    args = parser.parse_args(argv)
    if not args.model.is_file():
        parser.error(f"--model {args.model}: no such file")
    try:
        counts = parse_horizon_counts(args.horizons)
    except ProfileError as error:
        parser.error(str(error))
    result = {
        "model": str(args.model),
        "threads": args.threads,
        "onnxruntime": onnxruntime.__version__,
        "cpu_count": os.cpu_count(),
        "load_average_before": os.getloadavg(),
        "profiles": [profile(args.model, args.threads, k, args.runs, args.warmup, args.top) for k in counts],
        "load_average_after": os.getloadavg(),
    }
    for entry in result["profiles"]:
        print(
            f"K={entry['horizons']}: run median {entry['run_median_ms']} ms, min {entry['run_min_ms']} ms, "
            f"kernels {entry['kernel_ms_per_run']} ms per run"
        )
        for row in entry["per_operator_type"][: args.top]:
            print(f"  {row['op']:<28} {row['ms_per_run']:8.3f} ms  {100 * row['share']:5.1f} %")
        print("  top nodes:")
        for row in entry["top_nodes"]:
            print(f"  {row['node']:<60} {row['op']:<20} {row['ms_per_run']:8.3f} ms")
    if args.output:
        args.output.parent.mkdir(parents=True, exist_ok=True)
        args.output.write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
