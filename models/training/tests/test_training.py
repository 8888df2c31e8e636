import json

import numpy as np
import pytest
import torch

from evgate_train.augment import Augmentation, apply
from evgate_train.checkpoint import load_checkpoint
from evgate_train.sequence import load_sequence
from evgate_train.train import TrainingSetupError, build_parser, train
from evgate_train.windows import Crop, reference_voxel, training_window


def _args(synthetic_dir, run_dir, steps, *extra):
    return build_parser().parse_args(
        [
            "--data", str(synthetic_dir), "--manifest", str(synthetic_dir / "manifest.json"),
            "--run-dir", str(run_dir), "--size", "XS", "--steps", str(steps), "--batch", "2",
            "--chunk-windows", "2", "--crop", "32", "--checkpoint-every", "1", "--warmup", "1", *extra,
        ]
    )


def test_training_logs_checkpoints_and_resumes(synthetic_dir, tmp_path):
    run = tmp_path / "run"
    train(_args(synthetic_dir, run, 2, "--keep-checkpoints-at", "1"))
    assert load_checkpoint(run / "checkpoint.pt").step == 2
    assert load_checkpoint(run / "checkpoint-step1.pt").step == 1
    train(_args(synthetic_dir, run, 3, "--resume"))
    records = [json.loads(line) for line in (run / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in records] == [1, 2, 3]
    assert all(np.isfinite(r["total"]) and r["contrast"] >= 0 for r in records)
    assert load_checkpoint(run / "checkpoint.pt").step == 3


def test_resume_refuses_another_manifest(synthetic_dir, tmp_path):
    run = tmp_path / "run"
    train(_args(synthetic_dir, run, 1))
    other = tmp_path / "other-manifest.json"
    other.write_text("{}")
    args = _args(synthetic_dir, run, 2, "--resume")
    args.manifest = other
    with pytest.raises(TrainingSetupError, match="trained on manifest"):
        train(args)


def _object_event_share(window, mask_index: int = 0) -> float:
    events = window.future_events[mask_index]
    inside = window.future_mask[mask_index][events.y.astype(int), events.x.astype(int)] > 0
    return float(inside.mean())


def test_flips_move_masks_flow_and_events_alike(synthetic_dir):
    sequence = load_sequence(synthetic_dir / "slide-0.npz")
    rng = np.random.default_rng(0)
    window = training_window(
        sequence, 2, Crop(left=0, top=0, size=48), 10_000, rng, reference_voxel(sequence, 2)
    )
    flipped = apply(window, Augmentation(True, True, True), 48)
    np.testing.assert_array_equal(flipped.mask, window.mask[::-1, ::-1])
    np.testing.assert_array_equal(flipped.voxel, -window.voxel[:, ::-1, ::-1])
    # The square slides right: after a horizontal flip its flow points left.
    moving = window.flow_valid & (np.abs(window.future_flow[:, 0]) > 0)
    assert (window.future_flow[:, 0][moving] > 0).all()
    assert (flipped.future_flow[:, 0][moving[:, ::-1, ::-1]] < 0).all()
    # Events stay on the (flipped) object: the share of future events inside the future mask
    # (events fire only on the square) is unchanged by the flip.
    assert _object_event_share(flipped) == pytest.approx(_object_event_share(window))
    assert flipped.future_events[0].on.tolist() == (~window.future_events[0].on).tolist()


def test_object_crops_contain_an_object(synthetic_dir):
    from evgate_train.batches import ChunkSampler

    sequence = load_sequence(synthetic_dir / "slide-0.npz")
    sampler = ChunkSampler([sequence], 2, 32, 100, augment=False, seed=3, object_crop_share=1.0)
    for _ in range(20):
        start = int(sampler.rng.integers(len(sequence.ref_ts) - 1))
        crop = sampler._crop(sequence, start)
        frame = sequence.masks[sequence.grid_index(int(sequence.ref_ts[start]))]
        assert 0 <= crop.left <= sequence.width - 32 and 0 <= crop.top <= sequence.height - 32
        assert frame[crop.top : crop.top + 32, crop.left : crop.left + 32].any()


def test_stop_at_step_keeps_the_longer_schedule(synthetic_dir, tmp_path):
    from evgate_train.train import learning_rate

    run = tmp_path / "run"
    train(_args(synthetic_dir, run, 4, "--stop-at-step", "2"))
    records = [json.loads(line) for line in (run / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in records] == [1, 2]
    assert records[1]["lr"] == pytest.approx(learning_rate(1, 4, 2e-3, 1))
    assert load_checkpoint(run / "checkpoint.pt").step == 2


def test_init_from_starts_a_new_run_from_another_runs_weights(synthetic_dir, tmp_path):
    import torch

    source = tmp_path / "source"
    train(_args(synthetic_dir, source, 2))
    run = tmp_path / "fine-tune"
    train(_args(synthetic_dir, run, 1, "--init-from", str(source / "checkpoint.pt"), "--stop-at-step", "1"))
    records = [json.loads(line) for line in (run / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in records] == [1]
    tuned, original = load_checkpoint(run / "checkpoint.pt"), load_checkpoint(source / "checkpoint.pt")
    assert tuned.step == 1
    # One small step away from the source weights, not from a fresh initialisation.
    distance = sum(float((a - b).abs().sum()) for a, b in zip(tuned.network.parameters(), original.network.parameters()))
    fresh = sum(float(p.abs().sum()) for p in tuned.network.parameters())
    assert 0 < distance < 0.2 * fresh


def test_forecast_ramp_scales_only_the_forecast_terms():
    from evgate_train.objective import LossWeights
    from evgate_train.train import forecast_ramped

    weights = LossWeights(dice=0.5, positive=5.0, flow=0.1, contrast=1.0)
    start, middle, done = (forecast_ramped(weights, step, 100) for step in (0, 50, 150))
    assert (start.future_mask, start.flow, start.contrast) == (0.0, 0.0, 0.0)
    assert middle.contrast == pytest.approx(0.5) and middle.future_mask == pytest.approx(0.5)
    assert done == weights and (start.dice, start.positive) == (0.5, 5.0)


def test_arrival_flow_target_moves_the_whole_future_footprint(synthetic_dir):
    sequence = load_sequence(synthetic_dir / "slide-0.npz")
    crop = Crop(left=0, top=0, size=48)
    voxel = reference_voxel(sequence, 2)
    forward = training_window(sequence, 2, crop, 100, np.random.default_rng(0), voxel)
    arrival = training_window(sequence, 2, crop, 100, np.random.default_rng(0), voxel, flow_at_arrival=True)
    # The square slides right: the pixels it reaches by t + h (future mask, not mask at t) carry
    # the background's forward flow, but its own flow as the arrival target.
    k = int(np.argmax(arrival.horizons_ms))
    reached = (arrival.future_mask[k] > 0) & (arrival.mask == 0)
    assert reached.any()
    assert (np.abs(forward.future_flow[k, 0][reached]) < 1e-3).all() or not forward.flow_valid[k][reached].all()
    object_dx = forward.future_flow[k, 0][arrival.mask > 0].mean()
    assert object_dx > 0.5
    np.testing.assert_allclose(arrival.future_flow[k, 0][reached], object_dx, rtol=0.05)
    assert arrival.flow_valid[k][reached].all()
    # Outside every future footprint the target is unchanged.
    outside = arrival.future_mask[k] == 0
    np.testing.assert_array_equal(arrival.future_flow[k][:, outside], forward.future_flow[k][:, outside])


def test_loader_workers_draw_different_chunks_and_train(synthetic_dir, tmp_path):
    from evgate_train.batches import ChunkSampler
    from evgate_train.loader import chunk_batches

    sequences = [load_sequence(p) for p in sorted(synthetic_dir.rglob("*.npz"))]
    sampler = ChunkSampler(sequences, 2, 32, 500, True, seed=3)
    drawn = chunk_batches(sampler, 2, workers=2, seed=3)
    voxels = [next(drawn)[0].voxel for _ in range(4)]
    assert all(v.shape == (2, 2, 32, 32) for v in voxels)
    # Two workers with one seed each: the first batches of the two streams differ.
    assert not all(np.array_equal(voxels[0].numpy(), v.numpy()) for v in voxels[1:])
    run = tmp_path / "run"
    train(_args(synthetic_dir, run, 2, "--loader-workers", "2"))
    assert load_checkpoint(run / "checkpoint.pt").step == 2


def test_time_budget_ends_the_run_and_saves_its_last_step(synthetic_dir, tmp_path):
    from evgate_train.train import learning_rate

    run = tmp_path / "run"
    train(_args(synthetic_dir, run, 1000, "--time-budget-s", "1e-9", "--checkpoint-every", "100"))
    assert not (run / "checkpoint.pt").exists()
    train(_args(synthetic_dir, tmp_path / "run2", 1000, "--time-budget-s", "3", "--checkpoint-every", "100"))
    records = [json.loads(line) for line in (tmp_path / "run2" / "log.jsonl").read_text().splitlines()]
    assert 0 < len(records) < 1000
    assert load_checkpoint(tmp_path / "run2" / "checkpoint.pt").step == len(records)
    # The decay is paced by the budget: at the budget's end the rate is near its floor.
    assert learning_rate(500, 1000, 1.0, 1, elapsed_share=1.0) == pytest.approx(0.1)
    assert learning_rate(500, 1000, 1.0, 1, elapsed_share=0.0) > 0.5


def test_training_rejects_a_cuda_device_torch_cannot_see(synthetic_dir, tmp_path, monkeypatch):
    import torch

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(TrainingSetupError, match="no CUDA device"):
        train(_args(synthetic_dir, tmp_path / "run", 1, "--device", "cuda"))



@pytest.mark.parametrize("variant", ["none", "reference"])
def test_switching_time_conditioning_keeps_every_shared_weight(variant):
    from evgate_train.checkpoint import with_time_conditioning
    from evgate_train.network import NetworkConfig, SuppressionNetwork

    original = SuppressionNetwork(NetworkConfig(size="XS", time_conditioning="position-aware"))
    switched = with_time_conditioning(original, variant)
    assert switched.config.time_conditioning == variant
    source, weights = original.state_dict(), switched.state_dict()
    outside = [name for name in source if not name.startswith("time_conditioning.")]
    assert outside and all(torch.equal(weights[name], source[name]) for name in outside)
    atc = [name for name in weights if name.startswith("time_conditioning.")]
    if variant == "none":
        assert atc == []
    else:
        # Same parameters, another query: the ablation changes only how they are used.
        assert atc and all(torch.equal(weights[name], source[name]) for name in atc)


def test_init_time_conditioning_fine_tunes_the_switched_network(synthetic_dir, tmp_path):
    source = tmp_path / "source"
    train(_args(synthetic_dir, source, 1))
    run = tmp_path / "none"
    train(_args(synthetic_dir, run, 1, "--init-from", str(source / "checkpoint.pt"), "--init-time-conditioning", "none"))
    assert load_checkpoint(run / "checkpoint.pt").network.config.time_conditioning == "none"


def test_init_time_conditioning_without_init_from_is_refused(synthetic_dir, tmp_path):
    with pytest.raises(TrainingSetupError, match="--init-time-conditioning none: needs --init-from"):
        train(_args(synthetic_dir, tmp_path / "run", 1, "--init-time-conditioning", "none"))
