"""Networks with other inputs than the runtime's 2-bin voxel grid: more time bins, the
motion-compensated channel (training and Python evaluation only)."""

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from evgate_train.augment import Augmentation, augmented_voxel
from evgate_train.checkpoint import with_input_channels
from evgate_train.evaluate import evaluate_sequence
from evgate_train.export import RuntimeInputError, export
from evgate_train.network import NetworkConfig, SuppressionNetwork
from evgate_train.sequence import load_sequence
from evgate_train.streams import StreamSampler
from evgate_train.voxel import accumulate


def first_convolution(network: SuppressionNetwork, grid: np.ndarray) -> torch.Tensor:
    convolution = network.downsamples[0][0]
    return F.conv2d(torch.from_numpy(grid)[None], convolution.weight, convolution.bias, stride=2, padding=1)


def test_rebinned_first_convolution_answers_the_finer_raw_grid_as_before():
    rng = np.random.default_rng(0)
    t, x, y, on = rng.integers(0, 50_001, 800), rng.integers(0, 32, 800), rng.integers(0, 32, 800), rng.integers(0, 2, 800)
    network = SuppressionNetwork(NetworkConfig(size="XS"))
    rebinned = with_input_channels(network, 5, False)
    assert rebinned.config.input_channels == 5
    before = first_convolution(network, accumulate(t, x, y, on, 50_000, 32, 32))
    after = first_convolution(rebinned, accumulate(t, x, y, on, 50_000, 32, 32, bins=5))
    torch.testing.assert_close(after, before, atol=1e-5, rtol=1e-5)
    shared = {k: v for k, v in network.state_dict().items() if not k.startswith("downsamples.0.0.")}
    for name, weight in shared.items():
        torch.testing.assert_close(rebinned.state_dict()[name], weight)


def test_a_new_compensated_channel_starts_without_effect():
    network = SuppressionNetwork(NetworkConfig(size="XS")).eval()
    widened = with_input_channels(network, 2, True).eval()
    voxel = torch.randn(1, 2, 32, 48, generator=torch.Generator().manual_seed(1))
    compensated = torch.rand(1, 1, 32, 48)
    horizons = torch.tensor([[50.0, 100.0]])
    with torch.no_grad():
        plain = network(voxel, horizons, network.initial_states(1, 32, 48))
        with_channel = widened(torch.cat([voxel, compensated], 1), horizons, widened.initial_states(1, 32, 48))
    torch.testing.assert_close(with_channel.mask_logits, plain.mask_logits)
    torch.testing.assert_close(with_channel.future_mask_logits, plain.future_mask_logits)


def test_polarity_inversion_negates_the_voxel_bins_only():
    grid = np.arange(3 * 4 * 4, dtype=np.float32).reshape(3, 4, 4)
    inverted = augmented_voxel(grid, Augmentation(False, False, True), voxel_bins=2)
    np.testing.assert_array_equal(inverted[:2], -grid[:2])
    np.testing.assert_array_equal(inverted[2], grid[2])


def test_streams_build_the_channels_the_network_takes(synthetic_dir):
    paths = sorted(synthetic_dir.rglob("*.npz"))
    config = NetworkConfig(size="XS", voxel_bins=3, motion_compensated_channel=True)
    sampler = StreamSampler(paths, 2, 2, 48, 96, 3, 0, augment=True, seed=5, network=config)
    step = sampler.step()
    assert step.windows[0].voxel.shape == (2, 4, 48, 96)
    assert all(v.shape == (4, 48, 96) for v in sampler.played_voxels(0))
    # The compensated channel counts events: it is never negative, whatever the polarity draw.
    assert (step.windows[0].voxel[:, 3] >= 0).all()


@pytest.mark.parametrize(
    "config, named",
    [
        (NetworkConfig(size="XS", voxel_bins=5), "takes 5 voxel bins;"),
        (NetworkConfig(size="XS", motion_compensated_channel=True), "2 voxel bins and the motion-compensated channel"),
    ],
)
def test_export_refuses_an_input_the_runtime_does_not_build(tmp_path, config, named):
    with pytest.raises(RuntimeInputError, match=named):
        export(SuppressionNetwork(config), tmp_path / "model.onnx", 32, 48, "0" * 64, 0)
    assert not (tmp_path / "model.onnx").exists()


def test_evaluation_builds_the_input_the_checkpoint_takes(synthetic_dir):
    config = NetworkConfig(size="XS", voxel_bins=3, motion_compensated_channel=True)
    sequence = load_sequence(sorted(synthetic_dir.rglob("*.npz"))[0])
    scores = evaluate_sequence(SuppressionNetwork(config), sequence, [100.0], with_baselines=False, max_seconds=0.1)
    assert scores["current"].frames
