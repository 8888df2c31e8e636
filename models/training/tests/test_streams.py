import numpy as np
import pytest
import torch

from evgate_train.jitter import JitterRanges
from evgate_train.network import NetworkConfig, SuppressionNetwork
from evgate_train.objective import LossWeights
from evgate_train.streams import StreamSampler, StreamSetupError
from evgate_train.train import carried_states, replayed_states, train_step


def _sampler(synthetic_dir, streams=3, windows=2, seed=5, jitter=None) -> StreamSampler:
    paths = sorted(synthetic_dir.rglob("*.npz"))
    return StreamSampler(paths, streams, windows, 48, 96, 3, 0, augment=True, seed=seed, jitter=jitter)


def test_each_slot_plays_its_sequence_window_after_window_until_it_ends(synthetic_dir):
    sampler = _sampler(synthetic_dir)
    references = 6  # the synthetic sequence's reference times
    previous = [None] * sampler.streams
    restarts = 0
    for _ in range(12):
        step = sampler.step()
        for slot, cursor in enumerate(sampler.cursors):
            played = cursor.next_reference - sampler.windows_per_step
            if step.starts[slot]:
                restarts += 1
                assert played == cursor.first_reference < sampler.windows_per_step
                assert previous[slot] is None or previous[slot][1] + sampler.windows_per_step > references
            else:
                # Same sequence, crop and augmentation; the next windows in time.
                assert (cursor.sequence, cursor.crop, cursor.augmentation) == previous[slot][0]
                assert played == previous[slot][1]
            previous[slot] = ((cursor.sequence, cursor.crop, cursor.augmentation), cursor.next_reference)
        assert len(step.windows) == sampler.windows_per_step
        assert step.windows[0].voxel.shape == (sampler.streams, 2, 48, 96)
    assert restarts > sampler.streams  # streams ended and new ones began


def test_sequences_are_taken_in_shuffled_passes(synthetic_dir):
    sampler = _sampler(synthetic_dir, streams=1, windows=3)
    for _ in range(10):
        sampler.step()
    taken = sampler.order[: sampler.position]
    for start in range(0, len(taken) - 1, 2):
        assert sorted(taken[start : start + 2]) == [0, 1]


@pytest.mark.parametrize("jitter", [None, JitterRanges()], ids=["plain", "jittered"])
def test_the_state_is_carried_across_steps_and_reset_where_a_stream_starts(synthetic_dir, jitter):
    torch.manual_seed(0)
    network = SuppressionNetwork(NetworkConfig(size="XS"))
    # Fixed weights and batch-norm statistics: the carried state must then be exactly what
    # playing the stream from its start produces, and zero where it starts.
    network.eval()
    optimiser = torch.optim.SGD(network.parameters(), lr=0.0)
    sampler = _sampler(synthetic_dir, streams=2, jitter=jitter)
    states = network.initial_states(2, 48, 96)
    seen_start_after_carry = False
    for index in range(8):
        drawn = sampler.step()
        entering = carried_states(states, drawn.starts)
        for slot in np.flatnonzero(drawn.starts):
            assert all(not s[slot].any() for s in entering)
        if index > 0 and drawn.starts.any() and not drawn.starts.all():
            seen_start_after_carry = True
        states, losses = train_step(network, optimiser, drawn, states, LossWeights())
        assert torch.isfinite(losses["total"])
        assert all(not s.requires_grad for s in states)
        for carried, replayed in zip(states, replayed_states(network, sampler, torch.device("cpu"))):
            torch.testing.assert_close(carried, replayed, rtol=1e-5, atol=1e-5)
    assert seen_start_after_carry


def test_a_cursor_for_other_data_is_refused(synthetic_dir):
    sampler = _sampler(synthetic_dir)
    sampler.step()
    state = sampler.state_dict()
    other = StreamSampler(sorted(synthetic_dir.rglob("*.npz"))[:1], 3, 2, 48, 96, 3, 0, True, 5)
    with pytest.raises(StreamSetupError, match="resume on the same --data"):
        other.load_state_dict(state)
