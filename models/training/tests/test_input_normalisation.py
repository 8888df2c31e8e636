"""The local input normalisation: magnitudes that do not depend on how densely the texture
fires, the two bins' ratio kept, and the separable box equal to the square one."""

import pytest
import torch
import torch.nn.functional as F

from evgate_train.checkpoint import with_input_normalisation
from evgate_train.input_normalisation import (
    LOCAL_WINDOW,
    InputNormalisationError,
    box_mean,
    check_input_normalisation,
    normalise_input,
)
from evgate_train.network import NetworkConfig, SuppressionNetwork


def _edge(height: int = 64, width: int = 64, every: int = 1) -> torch.Tensor:
    """A vertical edge of events at column 32, on every `every`-th row, both bins non-zero."""
    voxel = torch.zeros(1, 2, height, width)
    voxel[0, 0, ::every, 32] = 0.6
    voxel[0, 1, ::every, 32] = 1.8
    return voxel


def test_global_leaves_the_grid_as_given():
    voxel = torch.randn(1, 2, 16, 16)
    assert torch.equal(normalise_input(voxel, "global"), voxel)


def test_local_magnitude_does_not_depend_on_density_or_scale():
    dense, sparse = _edge(every=1), 7.0 * _edge(every=4)
    dense_out, sparse_out = normalise_input(dense, "local"), normalise_input(sparse, "local")
    # The same edge, fired by every row or every fourth row and 7x brighter, gets the same values.
    torch.testing.assert_close(sparse_out[0, :, ::4, 32], dense_out[0, :, ::4, 32], atol=1e-3, rtol=1e-3)
    # Under the global normalisation the two differ by the 7x.
    assert not torch.allclose(sparse[0, :, ::4, 32], dense[0, :, ::4, 32])


def test_local_keeps_the_ratio_of_the_bins_and_the_empty_cells():
    voxel = _edge(every=3) + 0.0
    voxel[0, :, 10, 5] = torch.tensor([-2.0, 0.5])
    out = normalise_input(voxel, "local")
    active = voxel != 0
    torch.testing.assert_close(out[0, 1][active[0, 1]] / out[0, 0][active[0, 0]], voxel[0, 1][active[0, 1]] / voxel[0, 0][active[0, 0]])
    assert torch.equal(out[~active], torch.zeros_like(out[~active]))
    assert torch.isfinite(out).all()


def test_local_of_an_empty_grid_is_empty():
    assert torch.equal(normalise_input(torch.zeros(1, 2, 32, 32), "local"), torch.zeros(1, 2, 32, 32))


def test_separable_box_equals_the_square_window():
    torch.manual_seed(2)
    image = torch.rand(2, 1, 40, 56)
    square = F.avg_pool2d(image, LOCAL_WINDOW, stride=1, padding=LOCAL_WINDOW // 2, count_include_pad=True)
    torch.testing.assert_close(box_mean(image), square, atol=1e-6, rtol=1e-5)


def test_unknown_normalisation_names_the_accepted_ones():
    with pytest.raises(InputNormalisationError, match="'median'.*global, local"):
        check_input_normalisation("median")
    with pytest.raises(InputNormalisationError):
        SuppressionNetwork(NetworkConfig(size="XS", input_normalisation="median"))


def test_switching_keeps_every_weight_and_changes_the_output():
    torch.manual_seed(3)
    network = SuppressionNetwork(NetworkConfig(size="XS")).eval()
    with torch.no_grad():
        for parameter in network.parameters():
            parameter.add_(0.1 * torch.randn_like(parameter))
    switched = with_input_normalisation(network, "local").eval()
    assert switched.config.input_normalisation == "local"
    for (name, weight), (_, other) in zip(network.state_dict().items(), switched.state_dict().items()):
        assert torch.equal(weight, other), name
    voxel = 3.0 * _edge(height=48, width=96)
    horizons = torch.tensor([[50.0]])
    with torch.no_grad():
        plain = network(voxel, horizons, network.initial_states(1, 48, 96)).mask_logits
        local = switched(voxel, horizons, switched.initial_states(1, 48, 96)).mask_logits
    assert (plain - local).abs().max() > 1e-3
