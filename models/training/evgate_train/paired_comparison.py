"""Paired comparison of two models of one `evaluate` report, by the shipping rule of
docs/evaluation.md: per metric, the 95 % percentile-bootstrap interval (4000 resamples of the
sequences, a fixed seed) of the mean per-sequence difference; a clear gain lies above zero.

    python -m evgate_train.paired_comparison --report runs/eval-val.json \\
        --baseline plain --candidate compensated --output runs/compare.json

For networks the runtime cannot run (another input), whose exports `evgate compare` cannot
score; the figures are the Python evaluator's frame metrics, not evgate-eval's event metrics.
"""

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

RESAMPLES = 4000
SEED = 20261203
METRICS = ("miou", "imo_iou", "piou", "sr50", "r50", "r50_small", "r50_medium", "r50_large")


class ComparisonSetupError(ValueError):
    """A report without the named models, their per-sequence scores or a shared sequence."""


def interval(differences: np.ndarray) -> tuple[float, float]:
    rng = np.random.default_rng(SEED)
    means = differences[rng.integers(0, len(differences), (RESAMPLES, len(differences)))].mean(axis=1)
    low, high = np.percentile(means, [2.5, 97.5])
    return float(low), float(high)


def compare(report: dict, baseline: str, candidate: str, keys: list[str]) -> list[dict]:
    models = report.get("models", {})
    for name in (baseline, candidate):
        if name not in models:
            raise ComparisonSetupError(f"model {name!r} is not in the report; it has: {', '.join(models) or 'none'}")
        if "per-sequence" not in models[name]:
            raise ComparisonSetupError(f"model {name!r} has no per-sequence scores; evaluate it again")
    sides = [{row["sequence"]: row["scores"] for row in models[name]["per-sequence"]} for name in (baseline, candidate)]
    shared = sorted(set(sides[0]) & set(sides[1]))
    if not shared:
        raise ComparisonSetupError(f"{baseline!r} and {candidate!r} share no sequence")
    rows = []
    for key in keys:
        for metric in METRICS:
            pairs = [
                (sides[0][s][key][metric], sides[1][s][key][metric])
                for s in shared
                # Reports from before the instance-area bands lack those metrics.
                if metric in sides[0][s].get(key, {}) and metric in sides[1][s].get(key, {})
                and not math.isnan(sides[0][s][key][metric]) and not math.isnan(sides[1][s][key][metric])
            ]
            if len(pairs) < 2:
                continue
            values = np.array(pairs)
            low, high = interval(values[:, 1] - values[:, 0])
            rows.append(
                {
                    "key": key,
                    "metric": metric,
                    "sequences": len(pairs),
                    "baseline": float(values[:, 0].mean()),
                    "candidate": float(values[:, 1].mean()),
                    "difference": float((values[:, 1] - values[:, 0]).mean()),
                    "interval": [low, high],
                    "verdict": "clear gain" if low > 0 else "clear loss" if high < 0 else "within noise",
                }
            )
    return rows


def table(rows: list[dict], baseline: str, candidate: str) -> str:
    lines = [
        f"{candidate} (candidate) against {baseline} (baseline), paired per sequence; in %:",
        f"{'key':<14}{'metric':<10}{'n':>4}{'baseline':>10}{'candidate':>11}{'gain':>8}{'95 % interval':>18}  verdict",
    ]
    for r in rows:
        low, high = (100 * v for v in r["interval"])
        lines.append(
            f"{r['key']:<14}{r['metric']:<10}{r['sequences']:>4}{100 * r['baseline']:>10.1f}{100 * r['candidate']:>11.1f}"
            f"{100 * r['difference']:>8.1f}{f'[{low:.1f}, {high:.1f}]':>18}  {r['verdict']}"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--report", type=Path, required=True, help="an evaluate report holding both models")
    parser.add_argument("--baseline", required=True, help="the baseline model's name in the report")
    parser.add_argument("--candidate", required=True, help="the candidate model's name in the report")
    parser.add_argument(
        "--keys", default="current,future-100ms", help="comma-separated score keys (current, future-<h>ms)"
    )
    parser.add_argument("--output", type=Path, help="also write the rows as JSON here")
    args = parser.parse_args(argv)
    try:
        report = json.loads(args.report.read_text())
    except (OSError, json.JSONDecodeError) as error:
        raise ComparisonSetupError(f"{args.report}: cannot read the report: {error}") from error
    rows = compare(report, args.baseline, args.candidate, [k for k in args.keys.split(",") if k])
    print(table(rows, args.baseline, args.candidate))
    if args.output is not None:
        args.output.parent.mkdir(parents=True, exist_ok=True)
        args.output.write_text(json.dumps({"baseline": args.baseline, "candidate": args.candidate, "rows": rows}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
