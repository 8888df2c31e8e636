import dataclasses

import numpy as np
import pytest
import torch
from synthetic_sequence import HEIGHT, SPEED_PX_PER_MS, WIDTH, events

from evgate_train.streams import StreamSampler
from evgate_train.contrast_maximisation import average_timestamp_loss, batched_average_timestamp_loss
from evgate_train.network import NetworkConfig, SuppressionNetwork
from evgate_train.objective import LossWeights, window_objective
from evgate_train.sequence import load_sequence


def _future_window(start_ms: float, horizon_ms: float, seed: int = 2):
    t, x, y, on = events(seed=seed)
    inside = (t >= start_ms * 1000) & (t <= (start_ms + horizon_ms) * 1000)
    return (
        torch.from_numpy(x[inside].astype(np.float32)),
        torch.from_numpy(y[inside].astype(np.float32)),
        torch.from_numpy(((t[inside] - start_ms * 1000) / 1000).astype(np.float32)),
        torch.from_numpy(on[inside].astype(bool)),
    )


def test_true_flow_scores_lower_than_zero_flow_on_simulated_events():
    x, y, t_ms, on = _future_window(100.0, 80.0)
    assert len(x) > 200
    true_velocity = torch.zeros(2, HEIGHT, WIDTH)
    true_velocity[0] = SPEED_PX_PER_MS  # only the square's pixels fire, so a uniform field is exact
    zero = average_timestamp_loss(x, y, t_ms, on, torch.zeros(2, HEIGHT, WIDTH), 80.0)
    true = average_timestamp_loss(x, y, t_ms, on, true_velocity, 80.0)
    wrong_direction = average_timestamp_loss(x, y, t_ms, on, -true_velocity, 80.0)
    assert float(true) < float(zero) < float(wrong_direction)


def test_loss_has_a_gradient_towards_the_true_flow():
    x, y, t_ms, on = _future_window(100.0, 80.0)
    velocity = torch.full((2, HEIGHT, WIDTH), 0.0)
    velocity[0] = 0.5 * SPEED_PX_PER_MS
    velocity.requires_grad_(True)
    average_timestamp_loss(x, y, t_ms, on, velocity, 80.0).backward()
    # Increasing the horizontal velocity towards the truth must lower the loss.
    assert float(velocity.grad[0].sum()) < 0


def _random_window(rng: np.random.Generator, count: int, duration_ms: float, on_share: float):
    return (
        torch.from_numpy(rng.integers(0, WIDTH, count).astype(np.float32)),
        torch.from_numpy(rng.integers(0, HEIGHT, count).astype(np.float32)),
        torch.from_numpy(np.sort(rng.uniform(0, duration_ms, count)).astype(np.float32)),
        torch.from_numpy(rng.random(count) < on_share),
    )


def _assert_batched_matches_loop(windows: list, velocity: torch.Tensor, durations_ms: list[float]) -> None:
    """Loss and velocity gradient of the batched function against one call per window."""
    looped_velocity = velocity.clone().requires_grad_(True)
    looped = torch.stack(
        [
            average_timestamp_loss(*window, looped_velocity[n], duration)
            for n, (window, duration) in enumerate(zip(windows, durations_ms))
        ]
    )
    looped.sum().backward()
    batched_velocity = velocity.clone().requires_grad_(True)
    segment = torch.cat([torch.full((len(w[0]),), n, dtype=torch.long) for n, w in enumerate(windows)])
    batched = batched_average_timestamp_loss(
        *(torch.cat([w[i] for w in windows]) for i in range(4)),
        segment,
        batched_velocity,
        torch.tensor(durations_ms, dtype=torch.float32),
    )
    batched.sum().backward()
    assert bool((looped > 0).all())
    torch.testing.assert_close(batched, looped, rtol=1e-5, atol=0.0)
    scale = float(looped_velocity.grad.abs().max())
    assert scale > 0
    torch.testing.assert_close(batched_velocity.grad, looped_velocity.grad, rtol=1e-4, atol=1e-5 * scale)


def test_batched_loss_equals_the_per_window_loss_on_random_events():
    rng = np.random.default_rng(5)
    durations = [80.0, 12.5, 100.0, 40.0, 60.0]
    windows = [
        _random_window(rng, 900, durations[0], 0.5),
        _random_window(rng, 60, durations[1], 0.3),
        _random_window(rng, 3000, durations[2], 1.0),  # no OFF event
        _random_window(rng, 250, durations[3], 0.0),  # no ON event
        _random_window(rng, 1, durations[4], 0.5),
    ]
    velocity = torch.from_numpy(rng.normal(0.0, 0.1, (5, 2, HEIGHT, WIDTH)).astype(np.float32))
    # Fast enough that most of the third window's events leave the image.
    velocity[2] *= 20.0
    _assert_batched_matches_loop(windows, velocity, durations)


def test_batched_loss_equals_the_per_window_loss_on_simulated_events():
    horizons = [(100.0, 80.0), (20.0, 30.0), (250.0, 100.0), (300.0, 15.0)]
    windows = [_future_window(start, horizon, seed) for seed, (start, horizon) in enumerate(horizons)]
    velocity = torch.zeros(len(windows), 2, HEIGHT, WIDTH)
    velocity[:, 0] = SPEED_PX_PER_MS
    velocity[1] = -velocity[1]
    velocity[3] += torch.from_numpy(np.random.default_rng(1).normal(0.0, 0.05, (2, HEIGHT, WIDTH)).astype(np.float32))
    _assert_batched_matches_loop(windows, velocity, [h for _, h in horizons])


def _contrast_by_pair_loop(velocity: torch.Tensor, batch, weights: LossWeights) -> torch.Tensor:
    """The objective's contrast term as it was before batching: one call per qualifying pair."""
    terms = []
    for sample, events_per_horizon in enumerate(batch.future_events):
        for k, window in enumerate(events_per_horizon):
            horizon = float(batch.horizons_ms[sample, k])
            if horizon < weights.contrast_min_horizon_ms or len(window.x) < weights.contrast_min_events:
                continue
            terms.append(
                average_timestamp_loss(
                    torch.from_numpy(window.x),
                    torch.from_numpy(window.y),
                    torch.from_numpy(window.t_ms),
                    torch.from_numpy(window.on),
                    velocity[sample, k],
                    horizon,
                )
            )
    return torch.stack(terms).mean()


@pytest.fixture(scope="module")
def synthetic_batch(synthetic_dir):
    paths = [synthetic_dir / name for name in ("slide-0.npz", "slide-1.npz")]
    sampler = StreamSampler(paths, 6, 1, 48, 48, 4, 2000, augment=True, seed=4)
    return sampler.step().windows[0]


def test_window_objective_contrast_equals_the_per_pair_loop(synthetic_batch):
    weights = LossWeights(contrast=1.0, contrast_min_horizon_ms=45.0, contrast_min_events=200)
    horizons = synthetic_batch.host_horizons_ms.reshape(-1)
    counts = np.array([len(e.x) for e in sum(synthetic_batch.future_events, [])])
    long_enough = horizons >= weights.contrast_min_horizon_ms
    enough_events = counts >= weights.contrast_min_events
    # Pairs left out by each rule alone, and pairs kept.
    assert (long_enough & ~enough_events).any() and (~long_enough & enough_events).any()
    assert (long_enough & enough_events).sum() > 1
    torch.manual_seed(0)
    network = SuppressionNetwork(NetworkConfig(size="XS"))
    out = network(synthetic_batch.voxel, synthetic_batch.horizons_ms, network.initial_states(6, 48, 48))
    # The untrained network's velocities are tiny; random ones make the warps matter.
    velocity = 0.1 * torch.randn_like(out.velocity)
    batched_velocity = velocity.clone().requires_grad_(True)
    contrast = window_objective(dataclasses.replace(out, velocity=batched_velocity), synthetic_batch, weights)[
        "contrast"
    ]
    looped_velocity = velocity.clone().requires_grad_(True)
    looped = _contrast_by_pair_loop(looped_velocity, synthetic_batch, weights)
    torch.testing.assert_close(contrast, looped, rtol=1e-5, atol=0.0)
    contrast.backward()
    looped.backward()
    scale = float(looped_velocity.grad.abs().max())
    torch.testing.assert_close(batched_velocity.grad, looped_velocity.grad, rtol=1e-4, atol=1e-5 * scale)


def test_window_objective_contrast_is_zero_when_no_pair_qualifies(synthetic_batch):
    weights = LossWeights(contrast_min_horizon_ms=1000.0)
    network = SuppressionNetwork(NetworkConfig(size="XS"))
    out = network(synthetic_batch.voxel, synthetic_batch.horizons_ms, network.initial_states(6, 48, 48))
    assert float(window_objective(out, synthetic_batch, weights)["contrast"]) == 0.0
