import json

import pytest
import torch

from evgate_train.checkpoint import save_checkpoint
from evgate_train.evaluate import EvaluationSetupError, evaluate_sequence, main, parse_model
from evgate_train.network import NetworkConfig, SuppressionNetwork
from evgate_train.sequence import load_sequence


def test_scores_every_reference_time_with_baselines(synthetic_dir):
    torch.manual_seed(0)
    network = SuppressionNetwork(NetworkConfig(size="XS"))
    sequence = load_sequence(synthetic_dir / "slide-0.npz")
    scores = evaluate_sequence(network, sequence, [50.0, 100.0], with_baselines=True)
    assert set(scores) == {
        "current", "future-50ms", "future-100ms", "no-forecast-50ms", "no-forecast-100ms", "linear-50ms", "linear-100ms",
    }
    # Ground truth exists at every reference time and 100 ms after each (the sequence ends 100 ms after the last).
    assert len(scores["current"].frames) == len(sequence.ref_ts)
    assert len(scores["future-100ms"].frames) == len(sequence.ref_ts)
    limited = evaluate_sequence(network, sequence, [100.0], with_baselines=False, max_seconds=0.1)
    assert len(limited["current"].frames) == 2 and "linear-100ms" not in limited


def test_report_is_written_per_preset(synthetic_dir, tmp_path):
    torch.manual_seed(0)
    checkpoint = tmp_path / "xs.pt"
    save_checkpoint(checkpoint, SuppressionNetwork(NetworkConfig(size="XS")), None, 3, "cd" * 32, {})
    report_path = tmp_path / "report.json"
    main(["--data", str(synthetic_dir), "--model", f"xs={checkpoint}", "--max-seconds", "0.1", "--output", str(report_path)])
    report = json.loads(report_path.read_text())
    model = report["models"]["xs"]
    assert model["steps"] == 3 and model["size"] == "XS"
    assert model["presets"]["synthetic-test"]["current"]["sequences"] == 2


def test_bad_model_spec_is_explained():
    with pytest.raises(EvaluationSetupError, match="expected NAME=CHECKPOINT"):
        parse_model("runs/S/checkpoint.pt")
