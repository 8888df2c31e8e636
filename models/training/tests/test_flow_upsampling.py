import pytest
import torch

from evgate_train.checkpoint import with_flow_upsampling
from evgate_train.decoder import upsample
from evgate_train.flow_upsampling import ConvexUpsampling, FlowUpsamplingError, check_flow_upsampling, neighbourhoods
from evgate_train.network import NetworkConfig, SuppressionNetwork

FACTOR = 4


def _forced(module: ConvexUpsampling, neighbour: int, gate: float) -> ConvexUpsampling:
    """All weight on one neighbour (row-major in the 3x3 window) and a constant gate."""
    with torch.no_grad():
        module.weight_logits.bias.fill_(-30.0)
        module.weight_logits.bias[neighbour] = 30.0
        module.gate.bias.fill_(gate)
    return module


def _upsampled(module: ConvexUpsampling, coarse: torch.Tensor) -> torch.Tensor:
    features = torch.randn(1, 8, coarse.shape[2] * FACTOR, coarse.shape[3] * FACTOR)
    return upsample(coarse, FACTOR) + module(coarse, *module.guidance(features))


def test_a_fresh_convex_upsampling_is_the_bilinear_one():
    torch.manual_seed(0)
    coarse = torch.randn(3, 2, 5, 7)
    torch.testing.assert_close(_upsampled(ConvexUpsampling(8, FACTOR), coarse), upsample(coarse, FACTOR))


def test_all_weight_on_the_centre_cell_with_the_gate_open_is_nearest_upsampling():
    torch.manual_seed(1)
    coarse = torch.randn(2, 2, 4, 6)
    module = _forced(ConvexUpsampling(8, FACTOR), neighbour=4, gate=1.0)
    nearest = coarse.repeat_interleave(FACTOR, dim=2).repeat_interleave(FACTOR, dim=3)
    torch.testing.assert_close(_upsampled(module, coarse), nearest)


def test_the_right_hand_neighbour_is_the_next_cell_and_the_edge_repeats():
    coarse = torch.arange(12, dtype=torch.float32).view(1, 1, 3, 4)
    module = _forced(ConvexUpsampling(8, FACTOR), neighbour=5, gate=1.0)
    shifted = torch.cat([coarse[..., 1:], coarse[..., -1:]], dim=-1)
    expected = shifted.repeat_interleave(FACTOR, dim=2).repeat_interleave(FACTOR, dim=3)
    torch.testing.assert_close(_upsampled(module, coarse), expected)


def test_an_open_gate_stays_within_the_neighbourhood():
    """A convex combination never leaves the range of the 3x3 cells: a small object's flow is
    not blended with values from outside its neighbourhood, as an unbounded head could."""
    torch.manual_seed(2)
    coarse = torch.randn(2, 2, 5, 5) * 10
    module = ConvexUpsampling(8, FACTOR)
    with torch.no_grad():
        module.weight_logits.weight.normal_(0, 3)
        module.gate.bias.fill_(1.0)
    result = _upsampled(module, coarse)
    around = neighbourhoods(coarse, FACTOR)
    assert (result >= around.amin(dim=1) - 1e-5).all() and (result <= around.amax(dim=1) + 1e-5).all()


def test_an_unknown_upsampling_names_the_accepted_ones():
    with pytest.raises(FlowUpsamplingError, match="'cubic'; accepted: bilinear, convex"):
        check_flow_upsampling("cubic")
    with pytest.raises(FlowUpsamplingError):
        SuppressionNetwork(NetworkConfig(size="XS", flow_upsampling="cubic"))


@pytest.mark.parametrize("warp_resolution", ["full", "half"])
def test_a_trained_network_gains_the_convex_path_without_changing_its_outputs(warp_resolution):
    torch.manual_seed(3)
    bilinear = SuppressionNetwork(NetworkConfig(size="XS")).eval()
    with torch.no_grad():
        for parameter in bilinear.parameters():
            parameter.add_(0.05 * torch.randn_like(parameter))
    convex = with_flow_upsampling(bilinear, "convex").eval()
    assert convex.config.flow_upsampling == "convex"
    voxel, horizons = torch.randn(2, 2, 32, 48), torch.tensor([[10.0, 100.0], [50.0, 20.0]])
    with torch.no_grad():
        before = bilinear(voxel, horizons, bilinear.initial_states(2, 32, 48), warp_resolution)
        after = convex(voxel, horizons, convex.initial_states(2, 32, 48), warp_resolution)
    assert before.future_flow.abs().max() > 0.1
    torch.testing.assert_close(after.future_flow, before.future_flow)
    torch.testing.assert_close(after.future_mask_logits, before.future_mask_logits)
    torch.testing.assert_close(after.mask_logits, before.mask_logits)


def test_the_convex_weights_learn_from_the_flow_loss():
    """The gate starts closed, yet the first step moves it, and the next the weights."""
    torch.manual_seed(4)
    network = SuppressionNetwork(NetworkConfig(size="XS", flow_upsampling="convex"))
    voxel, horizons = torch.randn(1, 2, 32, 48), torch.tensor([[100.0]])
    out = network(voxel, horizons, network.initial_states(1, 32, 48))
    out.future_flow.square().mean().backward()
    assert network.convex_upsampling.gate.weight.grad.abs().sum() > 0
