"""Summarises the interleaved Rust-bench runs of run-interleaved.sh into one table (Markdown on
stdout, JSON beside the runs): per export, threads and K, the median and range of the runs'
inference medians, the lowest single call, the median of the runs' CPU-time medians and the
load averages seen.

    python3 evidence/models/latency/summarise.py evidence/models/latency/interleaved-<date>
"""

import json
import statistics
import sys
from collections import defaultdict
from pathlib import Path


def main(directory: Path) -> int:
    runs = defaultdict(list)
    for path in sorted(directory.glob("rust-bench-*-rep*.json")):
        label = path.name.removeprefix("rust-bench-").split("-K")[0]
        report = json.loads(path.read_text())
        runs[(label, report["intra-threads"], len(report["horizons-ms"]))].append(report)
    if not runs:
        print(f"{directory}: no rust-bench-*-rep*.json runs", file=sys.stderr)
        return 1
    rows = []
    for (label, threads, horizons), reports in sorted(runs.items(), key=lambda item: (-item[0][1], -item[0][2], item[0][0])):
        medians = [r["inference"]["median-ms"] for r in reports]
        loads = [r[key][0] for r in reports for key in ("load-average-before", "load-average-after") if r.get(key)]
        rows.append(
            {
                "export": label,
                "threads": threads,
                "horizons": horizons,
                "runs": len(reports),
                "median-of-medians-ms": round(statistics.median(medians), 1),
                "run-medians-ms": [round(m, 1) for m in medians],
                "min-ms": round(min(r["inference"]["min-ms"] for r in reports), 1),
                "cpu-median-ms": round(statistics.median(r["inference-cpu"]["median-ms"] for r in reports), 1),
                "load-1min": [min(loads), max(loads)] if loads else None,
            }
        )
    print("| export | threads | K | median (median of runs) | run medians | min | CPU time median | load (1 min) |")
    print("|---|---|---|---|---|---|---|---|")
    for row in rows:
        load = "{:.1f}–{:.1f}".format(*row["load-1min"]) if row["load-1min"] else "unknown"
        medians = " / ".join(f"{m:.1f}" for m in row["run-medians-ms"])
        print(
            f"| {row['export']} | {row['threads']} | {row['horizons']} | {row['median-of-medians-ms']:.1f} ms | {medians} "
            f"| {row['min-ms']:.1f} ms | {row['cpu-median-ms']:.1f} ms | {load} |"
        )
    (directory / "summary.json").write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    sys.exit(main(Path(sys.argv[1])))
