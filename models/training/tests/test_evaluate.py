import json

import pytest
import torch

from evgate_train.checkpoint import save_checkpoint
from evgate_train.evaluate import EvaluationSetupError, evaluate_sequence, main, parse_model
from evgate_train.export import export
from evgate_train.network import NetworkConfig, SuppressionNetwork
from evgate_train.onnx_network import ExportError, load_export
from evgate_train.sequence import load_sequence


def test_scores_every_reference_time_with_baselines(synthetic_dir):
    torch.manual_seed(0)
    network = SuppressionNetwork(NetworkConfig(size="XS"))
    sequence = load_sequence(synthetic_dir / "slide-0.npz")
    scores = evaluate_sequence(network, sequence, [50.0, 100.0], with_baselines=True)
    assert set(scores) == {
        "current", "future-50ms", "future-100ms", "no-forecast-50ms", "no-forecast-100ms", "linear-50ms", "linear-100ms",
        "true-motion-50ms", "true-motion-100ms", "true-kinematics-50ms", "true-kinematics-100ms",
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
    # Per-sequence scores, for paired comparisons between models.
    assert len(model["per-sequence"]) == 2
    assert model["per-sequence"][0]["scores"]["current"]["frames"] > 0


def test_bad_model_spec_is_explained():
    with pytest.raises(EvaluationSetupError, match="expected NAME=CHECKPOINT"):
        parse_model("runs/S/checkpoint.pt")


def _perturbed_xs_network() -> SuppressionNetwork:
    torch.manual_seed(2)
    network = SuppressionNetwork(NetworkConfig(size="XS")).eval()
    with torch.no_grad():
        for parameter in network.parameters():
            parameter.add_(0.05 * torch.randn_like(parameter))
    return network


def test_an_export_scores_like_its_checkpoint(synthetic_dir, tmp_path):
    network = _perturbed_xs_network()
    checkpoint = tmp_path / "xs.pt"
    save_checkpoint(checkpoint, network, None, 5, "cd" * 32, {})
    exported = tmp_path / "xs.onnx"
    export(network, exported, 48, 96, "cd" * 32, 5, warp_resolution="half")
    report_path = tmp_path / "report.json"
    main([
        "--data", str(synthetic_dir), "--model", f"checkpoint={checkpoint}", "--model", f"export={exported}",
        "--warp-resolution", "half", "--horizons-ms", "50,100", "--max-seconds", "0.3", "--output", str(report_path),
    ])
    models = json.loads(report_path.read_text())["models"]
    assert models["export"]["warp_resolution"] == "half" and models["export"]["steps"] == 5
    for key in ("current", "future-50ms", "future-100ms"):
        want = models["checkpoint"]["presets"]["synthetic-test"][key]
        got = models["export"]["presets"]["synthetic-test"][key]
        assert got == pytest.approx(want, abs=1e-3, nan_ok=True), key


def test_an_export_refuses_another_warp_resolution_or_size(tmp_path):
    exported = tmp_path / "xs.onnx"
    export(_perturbed_xs_network(), exported, 48, 96, "cd" * 32, 5, warp_resolution="half")
    network = load_export(exported, threads=1).network
    with pytest.raises(ExportError, match="exported for one stream of 96x48"):
        network.initial_states(1, 64, 96)
    states = network.initial_states(1, 48, 96)
    with pytest.raises(ExportError, match="exported with warp resolution half; full was asked for"):
        network(torch.zeros(1, 2, 48, 96), torch.tensor([[50.0]]), states, "full")


def test_flow_variants_score_the_mask_moved_without_backward_warping(synthetic_dir):
    torch.manual_seed(0)
    network = SuppressionNetwork(NetworkConfig(size="XS"))
    sequence = load_sequence(synthetic_dir / "slide-0.npz")
    scores = evaluate_sequence(network, sequence, [100.0], with_baselines=False, flow_variants=True)
    assert {"rigid-100ms", "splat-100ms"} <= set(scores)
    assert len(scores["rigid-100ms"].frames) == len(scores["future-100ms"].frames) > 0
