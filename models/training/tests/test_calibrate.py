import json

import numpy as np
import pytest
import torch

from evgate_train.calibrate import (
    CalibrationError,
    dilated,
    f1_curve,
    main,
    mask_index,
    parse_radii,
    sequence_counts,
)
from evgate_train.export import export
from evgate_train.network import NetworkConfig, SuppressionNetwork
from evgate_train.onnx_network import load_export


def test_events_take_the_mask_of_the_gates_interval_rule():
    # evgate-core's documented example: horizons 10, 20, 40 µs-ms alike; mask 2 starts at 15
    # and mask 3 at 30 (midpoints rounded up).
    d_us = np.array([0, 14_999, 15_000, 29_999, 30_000, 60_000])
    assert mask_index(d_us, (10, 20, 40)).tolist() == [0, 0, 1, 1, 2, 2]


def test_the_curve_counts_kept_events_above_each_threshold():
    logits = np.array([-2.0, -1.0, 0.5, 1.0, 3.0])
    positives = np.array([False, True, False, True, True])
    thresholds = np.array([-3.0, 0.0, 0.75, 5.0])
    rows = {row["threshold-logit"]: row for row in f1_curve([sequence_counts(logits, positives, thresholds)], thresholds)}
    assert rows[-3.0]["kept"] == 5 and rows[-3.0]["recall"] == 1.0 and rows[-3.0]["precision"] == 0.6
    assert rows[0.0]["kept"] == 3 and rows[0.0]["precision"] == pytest.approx(2 / 3)
    assert rows[0.75]["precision"] == 1.0 and rows[0.75]["recall"] == pytest.approx(2 / 3)
    assert rows[0.75]["f1"] == rows[0.75]["pooled-f1"] == pytest.approx(0.8)
    # Nothing kept: precision is undefined, F1 is 0 since moving-object events were missed.
    assert rows[5.0] == {"threshold-logit": 5.0, "precision": 0.0, "recall": 0.0, "f1": 0.0, "pooled-f1": 0.0, "kept": 0}


def test_scores_are_averaged_over_sequences_as_evgate_eval_does():
    thresholds = np.array([0.0])
    # A busy sequence, all of it kept and half of it moving objects (F1 2/3), and a sparse one
    # whose single moving-object event is kept alone (F1 1); one without moving objects, whose
    # precision is 0 and whose recall and F1 are undefined.
    busy = sequence_counts(np.ones(100), np.arange(100) < 50, thresholds)
    sparse = sequence_counts(np.array([1.0, -1.0]), np.array([True, False]), thresholds)
    static = sequence_counts(np.array([1.0]), np.array([False]), thresholds)
    (row,) = f1_curve([busy, sparse, static], thresholds)
    assert row["f1"] == pytest.approx((2 / 3 + 1) / 2)
    assert row["recall"] == 1.0 and row["precision"] == pytest.approx((0.5 + 1 + 0) / 3)
    assert row["pooled-f1"] == pytest.approx(2 * 51 / (102 + 51))
    assert row["kept"] == 102


def test_calibration_reports_the_best_threshold_of_an_export(synthetic_dir, tmp_path):
    torch.manual_seed(3)
    exported = tmp_path / "xs.onnx"
    export(SuppressionNetwork(NetworkConfig(size="XS")).eval(), exported, 48, 96, "cd" * 32, 1, threshold_logit=0.25)
    assert load_export(exported, 1).network.metadata["evgate.threshold-logit"] == "0.25"
    report_path = tmp_path / "calibration.json"
    main(["--model", str(exported), "--data", str(synthetic_dir), "--output", str(report_path)])
    report = json.loads(report_path.read_text())
    # The synthetic scene's events all come from its moving square: keeping every event is best.
    assert report["events"] > 0 and report["moving-object-events"] == report["events"]
    assert report["best"]["f1"] == max(row["f1"] for row in report["curve"]) == 1.0
    assert report["best"]["threshold-logit"] == -6.0
    assert report["best"]["f1"] >= report["at-zero"]["f1"]


def test_calibration_needs_labelled_events(tmp_path):
    with pytest.raises(CalibrationError, match="no .npz sequences"):
        main(["--model", "x.onnx", "--data", str(tmp_path), "--output", str(tmp_path / "c.json")])


def test_a_dilated_mask_takes_the_largest_logit_of_its_square():
    logits = torch.full((2, 5, 5), -4.0)
    logits[0, 2, 2] = 3.0
    grown = dilated(logits, 1)
    assert torch.equal(dilated(logits, 0), logits)
    assert (grown[0, 1:4, 1:4] == 3.0).all() and grown[0].sum() == 9 * 3.0 - 16 * 4.0
    assert (grown[1] == -4.0).all()


def test_calibration_reports_each_dilation(synthetic_dir, tmp_path):
    torch.manual_seed(3)
    exported = tmp_path / "xs.onnx"
    export(SuppressionNetwork(NetworkConfig(size="XS")).eval(), exported, 48, 96, "cd" * 32, 1)
    report_path = tmp_path / "calibration.json"
    main(["--model", str(exported), "--data", str(synthetic_dir), "--output", str(report_path), "--dilations", "2"])
    report = json.loads(report_path.read_text())
    by_radius = {entry["dilation-px"]: entry for entry in report["dilations"]}
    assert sorted(by_radius) == [0, 2]
    assert by_radius[0]["at-zero"] == report["at-zero"]
    # A larger mask keeps every event the undilated one keeps.
    assert by_radius[2]["at-zero"]["kept"] >= by_radius[0]["at-zero"]["kept"]
    # The keep rule is the best F1 over every radius; the mask threshold the best undilated one.
    best = max(by_radius.values(), key=lambda entry: entry["best"]["f1"])
    choice = report["choice"]
    assert choice["threshold-logit"] == report["best"]["threshold-logit"]
    assert (choice["keep-dilation-px"], choice["keep-threshold-logit"], choice["f1"]) == (
        best["dilation-px"],
        best["best"]["threshold-logit"],
        best["best"]["f1"],
    )


@pytest.mark.parametrize("text", ["1,x", "-1", "1,1", ""])
def test_dilations_must_be_distinct_whole_pixels(text):
    with pytest.raises(CalibrationError, match="--dilations"):
        parse_radii(text)
