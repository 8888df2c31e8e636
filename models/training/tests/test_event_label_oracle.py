"""The event-label oracle on the sliding square: its geometry fixes what the labelled events
cover at each span."""

import json

import numpy as np
import pytest
from synthetic_sequence import SIDE, SPEED_PX_PER_MS

from evgate_train.event_label_oracle import (
    GROUND_TRUTH,
    OracleInputError,
    forecast_key,
    main,
    oracle_key,
    score_sequence,
)
from evgate_train.sequence import load_sequence


def test_a_long_span_covers_the_square_and_its_trail_a_short_one_only_the_square(synthetic_dir):
    sequence = load_sequence(synthetic_dir / "slide-0.npz")
    scores = {key: s.summary() for key, s in score_sequence(sequence, [5, 50], [0]).items()}
    long_span, short_span = scores[oracle_key(50, 0)], scores[oracle_key(5, 0)]
    assert long_span["false_negative_share"] < 0.1
    trail_share = 50 * SPEED_PX_PER_MS / SIDE
    assert long_span["false_positive_share"] == pytest.approx(trail_share, abs=0.15)
    assert short_span["false_positive_share"] < 0.15
    # Within 5 ms the textured square fires on only part of its pixels.
    assert short_span["false_negative_share"] > 0.5


def test_dilation_fills_the_short_span_towards_the_square(synthetic_dir):
    sequence = load_sequence(synthetic_dir / "slide-0.npz")
    scores = {key: s.summary() for key, s in score_sequence(sequence, [5], [0, 2]).items()}
    assert scores[oracle_key(5, 2)]["imo_iou"] > scores[oracle_key(5, 0)]["imo_iou"] + 0.2


def test_the_true_mask_moved_by_its_motion_meets_the_future_and_held_misses_it(synthetic_dir):
    sequence = load_sequence(synthetic_dir / "slide-0.npz")
    scores = {key: s.summary() for key, s in score_sequence(sequence, [10], [2], [100]).items()}
    # In 100 ms the square slides 15 px, more than its 14 px side.
    assert scores[forecast_key(GROUND_TRUTH, "held", 100)]["imo_iou"] < 0.05
    assert scores[forecast_key(GROUND_TRUTH, "true-motion", 100)]["imo_iou"] > 0.9
    # It slides at constant speed, but its mask snaps to whole pixels, and the parabola through
    # three of them 20 ms apart amplifies that snapping at 100 ms: past kinematics help, not fully.
    for mask_key in (GROUND_TRUTH, oracle_key(10, 2)):
        assert (
            scores[forecast_key(mask_key, "true-kinematics", 100)]["imo_iou"]
            > scores[forecast_key(mask_key, "held", 100)]["imo_iou"] + 0.2
        )


def test_the_report_has_every_span_and_dilation_per_preset(synthetic_dir, tmp_path, capsys):
    output = tmp_path / "oracle.json"
    assert main(["--data", str(synthetic_dir), "--spans-ms", "10,50", "--dilations-px", "0,3", "--output", str(output)]) == 0
    report = json.loads(output.read_text())
    assert report == json.loads(capsys.readouterr().out)
    keys = report["presets"]["synthetic-test"]
    assert sorted(keys) == sorted(oracle_key(s, r) for s in (10, 50) for r in (0, 3))
    assert keys[oracle_key(50, 0)]["sequences"] == 2


def test_a_sequence_without_labels_and_bad_flags_are_named(synthetic_dir, tmp_path, capsys):
    with np.load(synthetic_dir / "slide-0.npz") as archive:
        arrays = {key: archive[key] for key in archive.files if key != "events_label"}
    unlabelled = tmp_path / "unlabelled"
    unlabelled.mkdir()
    np.savez(unlabelled / "slide.npz", **arrays)
    with pytest.raises(OracleInputError, match="slide.npz: no events_label array"):
        score_sequence(load_sequence(unlabelled / "slide.npz"), [5], [0])
    assert main(["--data", str(unlabelled)]) == 2
    assert "no events_label array" in capsys.readouterr().err
    assert main(["--data", str(synthetic_dir), "--spans-ms", "80"]) == 2
    assert "--spans-ms '80': each value must be 1 to 50" in capsys.readouterr().err
    assert main(["--data", str(synthetic_dir), "--dilations-px", "a"]) == 2
    assert "--dilations-px 'a': expected comma-separated integers" in capsys.readouterr().err
    assert main(["--data", str(synthetic_dir), "--horizons-ms", "5"]) == 2
    assert "--horizons-ms '5': each value must be 10 to 100" in capsys.readouterr().err
    assert main(["--data", str(synthetic_dir), "--horizons-ms", "15"]) == 2
    assert "--horizons-ms 15 is not a multiple of the ground-truth grid's 10 ms step" in capsys.readouterr().err
