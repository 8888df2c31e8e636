"""The export's arrangement of the computation (export_network, export_gru,
factorised_attention) computes what the training network computes, in PyTorch itself."""

import onnx
import pytest
import torch

from evgate_train.convgru import ConvGRU
from evgate_train.export import export
from evgate_train.export_gru import gru_step
from evgate_train.export_network import export_forward
from evgate_train.factorised_attention import condition_horizons
from evgate_train.network import NetworkConfig, SuppressionNetwork
from evgate_train.time_conditioning import TimeConditioning

HEIGHT, WIDTH = 48, 96


def _perturbed(module: torch.nn.Module, scale: float = 0.05) -> torch.nn.Module:
    """Random, non-zero weights everywhere (fresh refinement heads are zero)."""
    with torch.no_grad():
        for parameter in module.parameters():
            parameter.add_(scale * torch.randn_like(parameter))
    return module.eval()


@pytest.mark.parametrize("spatial", [False, True])
def test_gru_step_equals_the_cell(spatial):
    torch.manual_seed(3)
    cell = _perturbed(ConvGRU(8, 16, spatial=spatial), scale=0.3)
    x, h = torch.randn(1, 8, 12, 20), torch.randn(1, 16, 12, 20)
    with torch.no_grad():
        torch.testing.assert_close(gru_step(cell, x, h), cell(x, h), atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize("variant", ["position-aware", "reference", "none"])
def test_factorised_attention_equals_per_horizon_copies(variant):
    torch.manual_seed(4)
    module = _perturbed(TimeConditioning(32, variant), scale=0.5)
    features = torch.randn(1, 32, 6, 9) * 3.0
    horizons = torch.tensor([0.0, 12.5, 60.0, 100.0])
    with torch.no_grad():
        per_horizon = module(features.expand(4, -1, -1, -1), horizons)
        factorised = condition_horizons(module, features, horizons)
        exact = module.double()(features.double().expand(4, -1, -1, -1), horizons.double())
    # Scores here span tens of units, so both float32 orders of arithmetic round visibly; the
    # factorised one must be as close to the float64 result as the per-horizon one.
    per_horizon_error = (per_horizon.double() - exact).abs().max().item()
    assert (factorised.double() - exact).abs().max().item() <= 2 * per_horizon_error + 1e-6
    torch.testing.assert_close(factorised, per_horizon, atol=1e-3, rtol=1e-4)


@pytest.mark.parametrize(
    "variant, input_normalisation, flow_upsampling",
    [
        ("position-aware", "global", "bilinear"),
        ("reference", "global", "bilinear"),
        ("none", "global", "bilinear"),
        ("position-aware", "local", "bilinear"),
        ("position-aware", "global", "convex"),
    ],
)
@pytest.mark.parametrize("global_context", [False, True])
@pytest.mark.parametrize("warp_resolution", ["half", "full"])
def test_export_forward_equals_the_network(variant, input_normalisation, flow_upsampling, global_context, warp_resolution):
    torch.manual_seed(5)
    config = NetworkConfig(
        size="XS",
        time_conditioning=variant,
        input_normalisation=input_normalisation,
        flow_upsampling=flow_upsampling,
        global_context=global_context,
    )
    network = _perturbed(SuppressionNetwork(config))
    voxel = torch.randn(1, 2, HEIGHT, WIDTH)
    states = [0.5 * torch.randn_like(s) for s in network.initial_states(1, HEIGHT, WIDTH)]
    horizons = torch.tensor([5.0, 40.0, 100.0])
    with torch.no_grad():
        out = network(voxel, horizons[None], states, warp_resolution)
        got = export_forward(network, voxel, horizons, states, warp_resolution)
    expected = [out.mask_logits, out.future_mask_logits, out.coarse_flow, *out.states]
    assert len(got) == len(expected)
    for index, (actual, wanted) in enumerate(zip(got, expected)):
        torch.testing.assert_close(actual, wanted, atol=1e-5, rtol=1e-5, msg=f"output {index}")


def test_exported_recurrent_cells_have_no_split_or_state_concatenation(tmp_path):
    torch.manual_seed(6)
    network = SuppressionNetwork(NetworkConfig(size="XS")).eval()
    path = tmp_path / "tiny.onnx"
    export(network, path, HEIGHT, WIDTH, manifest_sha256="cd" * 32, train_steps=1)
    graph = onnx.load(str(path)).graph
    states = {f"state_{i}" for i in range(4)}
    assert not [node.name for node in graph.node if node.op_type in ("Split", "Slice") and "recurrent" in node.name]
    assert not [node.name for node in graph.node if node.op_type == "Concat" and states & set(node.input)]
