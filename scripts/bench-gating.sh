#!/usr/bin/env bash
# The gating benchmark as BENCHMARKS.md records it: the production judge (benches/gating.rs,
# wall and thread-CPU time) and, in the same run when DV_PYTHON names a Python with
# dv-processing 2.0.4, dv-processing's EventMaskFilter on the same event count. Writes
# OUT (default target/bench/gating.json): M events/s per row and its share of memcpy.
#
#   DV_PYTHON=/path/to/venv/bin/python bash scripts/bench-gating.sh [OUT]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
out=${1:-$root/target/bench/gating.json}
cd "$root"
rm -rf target/criterion/gate target/criterion/gate-cpu
cargo bench -p evgate-benches --bench gating -- --noplot
dv_json=null
if [[ -n ${DV_PYTHON:-} ]]; then
    dv_json=$("$DV_PYTHON" benches/python/dv_mask_filter.py)
fi
mkdir -p "$(dirname "$out")"
python3 - "$out" "$dv_json" <<'PY'
import json, pathlib, subprocess, sys
out, dv = sys.argv[1], json.loads(sys.argv[2])
events = 1_000_000
groups = {}
for group in ("gate", "gate-cpu"):
    rows = {}
    for estimates in sorted(pathlib.Path("target/criterion", group).glob("*/new/estimates.json")):
        ns = json.loads(estimates.read_text())["median"]["point_estimate"]
        rows[estimates.parent.parent.name] = events / ns * 1e3
    memcpy = rows["memcpy"]
    groups[group] = {name: {"m-events-per-s": round(rate, 1), "share-of-memcpy": round(rate / memcpy, 3)}
                     for name, rate in rows.items()}
report = {
    "bench": "gating",
    "commit": subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip(),
    "events": events,
    "groups": groups,
    "dv-processing-event-mask-filter": dv,
}
if dv:
    for group in groups.values():
        for row in group.values():
            row["times-event-mask-filter"] = round(row["m-events-per-s"] / dv["m-events-per-s"], 2)
pathlib.Path(out).write_text(json.dumps(report, indent=2) + "\n")
print(json.dumps(report, indent=2))
PY
