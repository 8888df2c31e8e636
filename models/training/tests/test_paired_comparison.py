"""Paired comparison of two models of one evaluate report (evgate_train.paired_comparison)."""

import json

import pytest

from evgate_train.paired_comparison import ComparisonSetupError, compare, main


def report_of(baseline: list[float], candidate: list[float]) -> dict:
    def rows(values):
        return [
            {
                "sequence": f"val/boxes-{i}/sequence.npz",
                "preset": "boxes",
                "scores": {"future-100ms": {m: v for m in ("miou", "imo_iou", "piou", "sr50", "r50")}},
            }
            for i, v in enumerate(values)
        ]

    return {"models": {"plain": {"per-sequence": rows(baseline)}, "new": {"per-sequence": rows(candidate)}}}


def test_a_consistent_gain_is_clear_and_noise_is_not():
    baseline = [0.50, 0.60, 0.55, 0.70, 0.65, 0.58]
    gain = compare(report_of(baseline, [b + 0.02 for b in baseline]), "plain", "new", ["future-100ms"])
    assert {r["verdict"] for r in gain} == {"clear gain"}
    assert gain[0]["difference"] == pytest.approx(0.02) and gain[0]["sequences"] == 6
    noise = compare(report_of(baseline, [b + d for b, d in zip(baseline, [0.03, -0.03, 0.02, -0.02, 0.01, -0.01])]),
                    "plain", "new", ["future-100ms"])
    assert {r["verdict"] for r in noise} == {"within noise"}
    loss = compare(report_of(baseline, [b - 0.05 for b in baseline]), "new", "plain", ["future-100ms"])
    assert {r["verdict"] for r in loss} == {"clear gain"}


def test_an_unknown_model_lists_the_reports_models():
    with pytest.raises(ComparisonSetupError, match="model 'other' is not in the report; it has: plain, new"):
        compare(report_of([0.5, 0.6], [0.5, 0.6]), "plain", "other", ["future-100ms"])


def test_the_cli_prints_and_writes_the_rows(tmp_path, capsys):
    path = tmp_path / "report.json"
    path.write_text(json.dumps(report_of([0.5, 0.6, 0.7], [0.6, 0.7, 0.8])))
    assert main(["--report", str(path), "--baseline", "plain", "--candidate", "new", "--keys", "future-100ms",
                 "--output", str(tmp_path / "compare.json")]) == 0
    assert "future-100ms  miou" in capsys.readouterr().out
    rows = json.loads((tmp_path / "compare.json").read_text())["rows"]
    assert rows[0]["interval"] == pytest.approx([0.1, 0.1])
