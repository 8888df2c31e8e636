import pytest
import torch

from evgate_train.network import (
    WARP_RESOLUTIONS,
    InputSizeError,
    NetworkConfig,
    SuppressionNetwork,
    WarpResolutionError,
)
from evgate_train.sizes import UnknownSizeError
from evgate_train.time_conditioning import TimeConditioning, UnknownVariantError


@pytest.mark.parametrize("variant", ["position-aware", "reference", "none"])
def test_output_shapes(variant):
    torch.manual_seed(0)
    network = SuppressionNetwork(NetworkConfig(size="XS", time_conditioning=variant))
    states = network.initial_states(2, 48, 64)
    assert [tuple(s.shape) for s in states] == [(2, 8, 24, 32), (2, 16, 12, 16), (2, 32, 6, 8), (2, 64, 3, 4)]
    out = network(torch.randn(2, 2, 48, 64), torch.tensor([[0.0, 30.0, 100.0], [5.0, 50.0, 70.0]]), states)
    assert out.mask_logits.shape == (2, 1, 48, 64)
    assert out.future_mask_logits.shape == (2, 3, 48, 64)
    assert out.future_flow.shape == (2, 3, 2, 48, 64)
    assert out.coarse_flow.shape == (2, 3, 2, 6, 8)
    assert [s.shape for s in out.states] == [s.shape for s in states]


@pytest.mark.parametrize("warp_resolution", WARP_RESOLUTIONS)
def test_zero_horizon_forecast_is_the_current_mask(warp_resolution):
    torch.manual_seed(0)
    network = SuppressionNetwork(NetworkConfig(size="XS"))
    states = network.initial_states(1, 32, 32)
    out = network(torch.randn(1, 2, 32, 32), torch.tensor([[0.0]]), states, warp_resolution)
    assert torch.count_nonzero(out.future_flow) == 0
    torch.testing.assert_close(out.future_mask_logits[:, 0], out.mask_logits[:, 0])


def test_half_resolution_warp_follows_the_full_resolution_one():
    """Same weights, both warps: the half-resolution forecast is far closer to the
    full-resolution one than the unwarped mask is (the flows move logits by ~10 px here)."""
    torch.manual_seed(3)
    network = SuppressionNetwork(NetworkConfig(size="XS")).eval()
    with torch.no_grad():
        for parameter in network.parameters():
            parameter.add_(0.05 * torch.randn_like(parameter))
        voxel, horizons = torch.randn(1, 2, 64, 96), torch.tensor([[40.0, 100.0]])
        full = network(voxel, horizons, network.initial_states(1, 64, 96), "full")
        half = network(voxel, horizons, network.initial_states(1, 64, 96), "half")
    torch.testing.assert_close(half.mask_logits, full.mask_logits)
    torch.testing.assert_close(half.coarse_flow, full.coarse_flow)
    assert float(full.future_flow.abs().mean()) > 5.0
    unwarped = full.mask_logits.expand_as(full.future_mask_logits)
    warp_effect = (unwarped - full.future_mask_logits).abs().mean()
    assert (half.future_mask_logits - full.future_mask_logits).abs().mean() < 0.25 * warp_effect


def test_unknown_warp_resolution_lists_the_accepted_ones():
    network = SuppressionNetwork(NetworkConfig(size="XS"))
    with pytest.raises(WarpResolutionError, match="'quarter'; accepted: full, half"):
        network(torch.randn(1, 2, 32, 32), torch.tensor([[10.0]]), network.initial_states(1, 32, 32), "quarter")


def test_state_carries_information_across_windows():
    torch.manual_seed(0)
    network = SuppressionNetwork(NetworkConfig(size="XS"))
    voxel, horizon = torch.randn(1, 2, 32, 32), torch.tensor([[50.0]])
    first = network(voxel, horizon, network.initial_states(1, 32, 32))
    second = network(voxel, horizon, first.states)
    assert not torch.allclose(first.mask_logits, second.mask_logits)


def test_reference_atc_is_spatially_constant_and_position_aware_is_not():
    torch.manual_seed(0)
    features = torch.randn(1, 16, 4, 5)
    horizon = torch.tensor([60.0])
    for variant, constant in (("reference", True), ("position-aware", False)):
        update = TimeConditioning(16, variant).attention_update(features, horizon)
        spread = float(update.detach().std(dim=1).max())
        assert (spread < 1e-5) == constant, f"{variant}: spread {spread}"


def test_atc_depends_on_the_horizon():
    torch.manual_seed(0)
    features = torch.randn(2, 16, 4, 5)
    module = TimeConditioning(16, "position-aware")
    out = module(features, torch.tensor([10.0, 90.0]))
    same_features = module(features[:1].expand(2, -1, -1, -1), torch.tensor([10.0, 90.0]))
    assert not torch.allclose(same_features[0], same_features[1])
    assert out.shape == features.shape


def test_bad_sizes_and_variants_are_named():
    with pytest.raises(UnknownSizeError, match="unknown model size 'XL'; accepted: XS, S, M, L"):
        SuppressionNetwork(NetworkConfig(size="XL"))
    with pytest.raises(UnknownVariantError, match="accepted: position-aware, reference, none"):
        SuppressionNetwork(NetworkConfig(time_conditioning="global"))
    with pytest.raises(InputSizeError, match="50x32"):
        SuppressionNetwork(NetworkConfig(size="XS")).initial_states(1, 32, 50)


def test_s_model_fits_the_cpu_budget():
    """The S model's design target (issue 4): about 1 GFLOP per window at 346x260 with the
    infer service's 8 horizons, also with 3x3 ConvGRU gates in every stage (run S-v5c-gates), and
    recurrent states at strides 2, 4, 8 and 16."""
    from evgate_train.flops import gflops

    network = SuppressionNetwork(NetworkConfig(size="S")).eval()
    spatial_gates = SuppressionNetwork(NetworkConfig(size="S", first_spatial_gru_stage=0)).eval()
    assert gflops(network, 346, 260, horizons=8) < gflops(spatial_gates, 346, 260, horizons=8) <= 1.0
    assert [tuple(s.shape[2:]) for s in network.initial_states(1, 272, 352)] == [
        (136, 176), (68, 88), (34, 44), (17, 22)
    ]


def test_l_model_has_the_papers_width():
    assert NetworkConfig(size="L").state_channels == [64, 128, 256, 512]
