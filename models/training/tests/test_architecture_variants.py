"""A wider mask decoder, 3x3 gates in the shallow ConvGRUs, a wider encoder and the mask
decoder's global context: the ways of spending S's latency headroom on the current-instant mask,
each added to a trained network without changing what it computes."""

import pytest
import torch

from evgate_train.checkpoint import (
    CheckpointError,
    with_encoder_width,
    with_flow_upsampling,
    with_global_context,
    with_mask_decoder_width,
    with_spatial_gru_gates,
)
from evgate_train.network import ArchitectureError, NetworkConfig, SuppressionNetwork

HEIGHT, WIDTH = 32, 48


def _trained(config: NetworkConfig) -> SuppressionNetwork:
    """A network whose every weight and batch-norm statistic is non-trivial, as after training:
    fresh refinement heads are zero and fresh statistics the identity, which would hide a
    transformation that drops or misplaces them."""
    network = SuppressionNetwork(config)
    with torch.no_grad():
        for parameter in network.parameters():
            parameter.add_(0.05 * torch.randn_like(parameter))
        for module in network.modules():
            if isinstance(module, torch.nn.BatchNorm2d):
                module.running_mean.normal_(0, 0.1)
                module.running_var.uniform_(0.5, 1.5)
    return network.eval()


def _outputs(network: SuppressionNetwork, voxel: torch.Tensor, horizons: torch.Tensor, warp_resolution: str):
    with torch.no_grad():
        return network(voxel, horizons, network.initial_states(voxel.shape[0], HEIGHT, WIDTH), warp_resolution)


def _assert_same_outputs(before, after):
    torch.testing.assert_close(after.mask_logits, before.mask_logits)
    torch.testing.assert_close(after.future_mask_logits, before.future_mask_logits)
    torch.testing.assert_close(after.future_flow, before.future_flow)
    for new_state, old_state in zip(after.states, before.states):
        torch.testing.assert_close(new_state, old_state)


@pytest.mark.parametrize("warp_resolution", ["full", "half"])
@pytest.mark.parametrize("flow_upsampling", ["bilinear", "convex"])
def test_a_widened_mask_decoder_starts_computing_what_the_narrow_one_did(warp_resolution, flow_upsampling):
    torch.manual_seed(0)
    narrow = _trained(NetworkConfig(size="XS", flow_upsampling=flow_upsampling))
    wide = with_mask_decoder_width(narrow, 3).eval()
    assert wide.config.mask_decoder_width == 3 * narrow.config.mask_decoder_width
    assert wide.mask_decoder.reduce.weight.shape[0] == 3 * narrow.mask_decoder.reduce.weight.shape[0]
    voxel, horizons = torch.randn(2, 2, HEIGHT, WIDTH), torch.tensor([[10.0, 100.0], [50.0, 20.0]])
    _assert_same_outputs(_outputs(narrow, voxel, horizons, warp_resolution), _outputs(wide, voxel, horizons, warp_resolution))


def test_the_new_decoder_channels_are_live_and_learn():
    """Zero in and zero out would leave the new channels at zero forever: they are initialised
    as a fresh network's, so they carry features and their heads receive gradient at once."""
    torch.manual_seed(1)
    wide = with_mask_decoder_width(_trained(NetworkConfig(size="XS")), 2).train()
    narrow_width = wide.config.base
    features = {}
    wide.mask_decoder.convs[-1].register_forward_hook(lambda module, inputs, output: features.update(last=output))
    out = wide(torch.randn(2, 2, HEIGHT, WIDTH), torch.tensor([[100.0], [50.0]]), wide.initial_states(2, HEIGHT, WIDTH))
    assert features["last"][:, narrow_width:].abs().mean() > 0.1
    out.mask_logits.square().mean().backward()
    assert wide.mask_decoder.heads[-1].weight.grad[:, narrow_width:].abs().sum() > 0


@pytest.mark.parametrize("first_stage", [0, 1])
def test_shallow_gates_become_3x3_computing_what_the_1x1_ones_did(first_stage):
    torch.manual_seed(2)
    network = _trained(NetworkConfig(size="XS"))
    spatial = with_spatial_gru_gates(network, first_stage).eval()
    for stage, cell in enumerate(spatial.recurrent):
        assert isinstance(cell.gates, torch.nn.Sequential) == (stage >= first_stage)
    voxel, horizons = torch.randn(1, 2, HEIGHT, WIDTH), torch.tensor([[30.0, 100.0]])
    for warp_resolution in ("full", "half"):
        _assert_same_outputs(
            _outputs(network, voxel, horizons, warp_resolution), _outputs(spatial, voxel, horizons, warp_resolution)
        )


def test_both_changes_compose_with_the_convex_path():
    torch.manual_seed(3)
    network = _trained(NetworkConfig(size="XS"))
    changed = with_spatial_gru_gates(with_mask_decoder_width(with_flow_upsampling(network, "convex"), 2), 0).eval()
    voxel, horizons = torch.randn(1, 2, HEIGHT, WIDTH), torch.tensor([[100.0]])
    _assert_same_outputs(_outputs(network, voxel, horizons, "half"), _outputs(changed, voxel, horizons, "half"))


@pytest.mark.parametrize("first_spatial_stage", [0, 2])
def test_a_widened_encoder_computes_what_the_narrow_one_did_across_windows(first_spatial_stage):
    """Two windows in a row, so that the new state channels, which are no longer zero after
    the first, must still be invisible to the old channels and to every output."""
    torch.manual_seed(4)
    narrow = _trained(NetworkConfig(size="XS", first_spatial_gru_stage=first_spatial_stage, flow_upsampling="convex"))
    wide = with_encoder_width(narrow, 12).eval()
    assert wide.config.state_channels == [12, 24, 48, 96]
    assert wide.config.mask_decoder_width == narrow.config.mask_decoder_width
    horizons = torch.tensor([[10.0, 100.0]])
    narrow_states, wide_states = narrow.initial_states(1, HEIGHT, WIDTH), wide.initial_states(1, HEIGHT, WIDTH)
    with torch.no_grad():
        for _ in range(2):
            voxel = torch.randn(1, 2, HEIGHT, WIDTH)
            before = narrow(voxel, horizons, narrow_states, "half")
            after = wide(voxel, horizons, wide_states, "half")
            torch.testing.assert_close(after.mask_logits, before.mask_logits)
            torch.testing.assert_close(after.future_mask_logits, before.future_mask_logits)
            torch.testing.assert_close(after.future_flow, before.future_flow)
            for new_state, old_state in zip(after.states, before.states):
                torch.testing.assert_close(new_state[:, : old_state.shape[1]], old_state)
                assert new_state[:, old_state.shape[1] :].abs().mean() > 0.01
            narrow_states, wide_states = before.states, after.states


def test_the_new_encoder_channels_reach_the_outputs_after_training():
    torch.manual_seed(5)
    wide = with_encoder_width(_trained(NetworkConfig(size="XS")), 16).train()
    out = wide(torch.randn(2, 2, HEIGHT, WIDTH), torch.tensor([[100.0], [50.0]]), wide.initial_states(2, HEIGHT, WIDTH))
    (out.mask_logits.square().mean() + out.future_flow.square().mean()).backward()
    narrow_bottleneck = 8 * 8
    assert wide.mask_decoder.reduce.weight.grad[:, narrow_bottleneck:].abs().sum() > 0
    assert wide.flow_features.weight.grad[:, narrow_bottleneck:].abs().sum() > 0
    assert wide.mask_decoder.skip_projections[-1].weight.grad[:, 8:].abs().sum() > 0


@pytest.mark.parametrize("warp_resolution", ["full", "half"])
def test_global_context_starts_computing_what_the_network_did(warp_resolution):
    torch.manual_seed(6)
    network = _trained(NetworkConfig(size="XS", first_spatial_gru_stage=0))
    with_context = with_global_context(network).eval()
    assert with_context.config.global_context and with_context.global_context is not None
    voxel, horizons = torch.randn(2, 2, HEIGHT, WIDTH), torch.tensor([[10.0, 100.0], [50.0, 20.0]])
    _assert_same_outputs(_outputs(network, voxel, horizons, warp_resolution), _outputs(with_context, voxel, horizons, warp_resolution))
    assert with_global_context(with_context) is with_context


def test_global_context_opens_under_training():
    """The modulation starts at zero; one step must open it, or the context would stay unused."""
    torch.manual_seed(7)
    network = with_global_context(_trained(NetworkConfig(size="XS"))).train()
    voxel, horizons = torch.randn(2, 2, HEIGHT, WIDTH), torch.tensor([[100.0], [50.0]])
    network(voxel, horizons, network.initial_states(2, HEIGHT, WIDTH)).mask_logits.square().mean().backward()
    torch.optim.SGD(network.parameters(), lr=0.1).step()
    network.eval()
    with torch.no_grad():
        opened = network(voxel, horizons, network.initial_states(2, HEIGHT, WIDTH)).mask_logits
        network.global_context.modulation.weight.zero_()
        network.global_context.modulation.bias.zero_()
        closed = network(voxel, horizons, network.initial_states(2, HEIGHT, WIDTH)).mask_logits
    assert (opened - closed).abs().max() > 1e-4


def test_changes_that_would_drop_trained_weights_are_refused():
    network = SuppressionNetwork(NetworkConfig(size="XS", mask_decoder_width_factor=2, first_spatial_gru_stage=1))
    with pytest.raises(CheckpointError, match="encoder base channels 4: the network's encoder is already 8 wide"):
        with_encoder_width(network, 4)
    with pytest.raises(CheckpointError, match="mask decoder width factor 1: the network's is already 2"):
        with_mask_decoder_width(network, 1)
    with pytest.raises(CheckpointError, match="first spatial ConvGRU stage 2: the network already has 3x3 gates from stage 1"):
        with_spatial_gru_gates(network, 2)


@pytest.mark.parametrize(
    ("config", "message"),
    [
        (NetworkConfig(size="XS", mask_decoder_width_factor=0), "mask decoder width factor 0: must be 1"),
        (NetworkConfig(size="XS", first_spatial_gru_stage=5), r"first spatial ConvGRU stage 5: must be 0 to 4"),
        (NetworkConfig(size="XS", first_spatial_gru_stage=-1), r"first spatial ConvGRU stage -1: must be 0 to 4"),
        (NetworkConfig(size="S", encoder_base_channels=12), r"encoder base channels 12: must be the size's base width \(16\)"),
    ],
)
def test_an_impossible_architecture_is_named(config, message):
    with pytest.raises(ArchitectureError, match=message):
        SuppressionNetwork(config)
