import numpy as np
import pytest

from evgate_train.linear_extrapolation import extrapolate
from evgate_train.metrics import SequenceScores, frame_scores, matched_instances


def test_iou_miou_and_piou():
    truth = np.zeros((10, 10), np.uint8)
    truth[2:6, 2:6] = 1  # 16 px
    predicted = np.zeros((10, 10), bool)
    predicted[2:6, 4:8] = True  # 16 px, 8 shared
    events = np.zeros((10, 10), bool)
    events[2:6, 2:5] = True  # 12 event pixels: truth 12, predicted 4, shared 4
    scores = frame_scores(predicted, truth, events)
    assert scores.imo_iou == pytest.approx(8 / 24)
    assert scores.background_iou == pytest.approx(76 / 92)
    assert scores.miou == pytest.approx((8 / 24 + 76 / 92) / 2)
    assert scores.piou == pytest.approx(4 / 12)
    assert not scores.success


def test_recall_matches_instances_one_to_one():
    truth = np.zeros((12, 12), np.uint8)
    truth[1:4, 1:4] = 1
    truth[7:11, 7:11] = 2
    predicted = np.zeros((12, 12), bool)
    predicted[1:4, 1:4] = True  # exact match of instance 1
    predicted[7:8, 7:8] = True  # far too small for instance 2
    assert matched_instances(predicted, truth) == [(9, True), (16, False)]
    assert matched_instances(np.zeros((12, 12), bool), truth) == [(9, False), (16, False)]


def test_recall_is_split_by_instance_area():
    truth = np.zeros((40, 40), np.uint8)
    truth[0:5, 0:5] = 1  # 25 px: small
    truth[10:30, 10:30] = 2  # 400 px: medium
    truth[0:4, 30:34] = 3  # 16 px: small
    predicted = truth == 1
    scores = SequenceScores()
    scores.add(frame_scores(predicted, truth, None))
    scores.add(frame_scores(truth > 0, truth, None))
    summary = scores.summary()
    assert summary["r50"] == pytest.approx(4 / 6)
    assert summary["r50_small"] == pytest.approx(3 / 4)
    assert summary["r50_medium"] == pytest.approx(1 / 2)
    assert np.isnan(summary["r50_large"])


def test_empty_frame_is_a_success_with_undefined_imo_iou():
    scores = frame_scores(np.zeros((4, 4), bool), np.zeros((4, 4), np.uint8), None)
    assert np.isnan(scores.imo_iou) and scores.miou == 1.0 and scores.success


def test_linear_extrapolation_continues_the_motion():
    before = np.zeros((20, 40), bool)
    before[5:9, 2:6] = True
    now = np.zeros((20, 40), bool)
    now[5:9, 7:11] = True  # 5 px in 50 ms
    forecast = extrapolate(before, now, elapsed_ms=50.0, horizon_ms=100.0)
    expected = np.zeros((20, 40), bool)
    expected[5:9, 17:21] = True
    np.testing.assert_array_equal(forecast, expected)


def test_area_and_error_shares_are_pooled_over_the_sequence():
    from evgate_train.metrics import SequenceScores

    truth = np.zeros((10, 10), np.uint8)
    truth[2:6, 2:6] = 1  # 16 px
    smeared = np.zeros((10, 10), bool)
    smeared[2:6, 2:9] = True  # the object and the 12 px strip behind it: 28 px
    shrunk = np.zeros((10, 10), bool)
    shrunk[2:6, 2:4] = True  # half the object: 8 px
    scores = SequenceScores()
    scores.add(frame_scores(smeared, truth, None))
    scores.add(frame_scores(shrunk, truth, None))
    scores.add(frame_scores(np.zeros((10, 10), bool), np.zeros((10, 10), np.uint8), None))
    summary = scores.summary()
    assert summary["area_ratio"] == pytest.approx((28 + 8) / 32)
    assert summary["false_positive_share"] == pytest.approx(12 / 32)
    assert summary["false_negative_share"] == pytest.approx(8 / 32)

def test_false_positives_far_from_every_true_object_are_counted_apart():
    from evgate_train.metrics import NEAR_TRUTH_PX, SequenceScores

    truth = np.zeros((30, 40), np.uint8)
    truth[10:14, 10:14] = 1  # 16 px
    predicted = truth > 0
    predicted[10:14, 14 : 14 + NEAR_TRUTH_PX] = True  # an outline too wide: 4 x 5 px, near
    predicted[25:27, 30:33] = True  # a phantom object: 6 px, far
    scores = SequenceScores()
    scores.add(frame_scores(predicted, truth, None))
    summary = scores.summary()
    assert summary["false_positive_share"] == pytest.approx((20 + 6) / 16)
    assert summary["false_positive_far_share"] == pytest.approx(6 / 16)


def test_error_shares_are_undefined_without_any_true_object():
    from evgate_train.metrics import SequenceScores

    scores = SequenceScores()
    scores.add(frame_scores(np.ones((4, 4), bool), np.zeros((4, 4), np.uint8), None))
    assert np.isnan(scores.summary()["area_ratio"]) and np.isnan(scores.summary()["false_positive_share"])
