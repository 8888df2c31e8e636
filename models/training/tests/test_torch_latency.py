import json

import pytest
import torch

from evgate_train.checkpoint import save_checkpoint
from evgate_train.network import NetworkConfig, SuppressionNetwork
from evgate_train.torch_latency import LatencySetupError, main, parse_inputs


def test_times_each_input_size_and_horizon_count(tmp_path):
    network = SuppressionNetwork(NetworkConfig(size="XS"))
    save_checkpoint(tmp_path / "xs.pt", network, None, 3, "0" * 64, {})
    output = tmp_path / "latency.json"
    main([
        "--checkpoint", str(tmp_path / "xs.pt"), "--device", "cpu", "--inputs", "48x32,40x40",
        "--horizons", "1,3", "--runs", "3", "--warmup", "1", "--output", str(output),
    ])
    result = json.loads(output.read_text())
    assert [(r["input"], r["horizons"]) for r in result["results"]] == [
        ("48x32", 1), ("48x32", 3), ("40x40", 1), ("40x40", 3),
    ]
    assert all(0 < r["median_ms"] <= r["p90_ms"] for r in result["results"])
    assert result["size"] == "XS" and result["steps"] == 3


def test_rejects_malformed_sizes_and_missing_cuda(tmp_path, monkeypatch):
    with pytest.raises(LatencySetupError, match="'346-260': expected WIDTHxHEIGHT"):
        parse_inputs("346x260,346-260")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(LatencySetupError, match="no CUDA device"):
        main(["--checkpoint", str(tmp_path / "missing.pt"), "--device", "cuda"])
