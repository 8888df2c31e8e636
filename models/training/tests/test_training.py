import json

import numpy as np
import pytest
import torch

from evgate_train.augment import Augmentation, apply
from evgate_train.checkpoint import load_checkpoint
from evgate_train.sequence import load_sequence
from evgate_train.train import TrainingSetupError, build_parser, train
from evgate_train.windows import Crop, HorizonCountError, draw_horizons, reference_input, training_window


def _args(synthetic_dir, run_dir, steps, *extra):
    return build_parser().parse_args(
        [
            "--data", str(synthetic_dir), "--manifest", str(synthetic_dir / "manifest.json"),
            "--run-dir", str(run_dir), "--size", "XS", "--steps", str(steps), "--streams", "2",
            "--windows-per-step", "2", "--crop", "48x96", "--checkpoint-every", "1", "--warmup", "1", *extra,
        ]
    )


def _first_mask_loss(synthetic_dir, run_dir, *extra):
    """The mask loss logged at the first of two training steps run with `extra`."""
    train(_args(synthetic_dir, run_dir, 2, *extra))
    return json.loads((run_dir / "log.jsonl").read_text().splitlines()[0])["mask"]


def test_training_logs_checkpoints_and_resumes_the_same_data_stream(synthetic_dir, tmp_path):
    straight, split = tmp_path / "straight", tmp_path / "split"
    train(_args(synthetic_dir, straight, 5))
    train(_args(synthetic_dir, split, 5, "--stop-at-step", "2"))
    assert load_checkpoint(split / "checkpoint.pt").step == 2
    train(_args(synthetic_dir, split, 5, "--resume"))
    records = [json.loads(line) for line in (split / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in records] == [1, 2, 3, 4, 5]
    assert all(np.isfinite(r["total"]) for r in records)
    finished, resumed = load_checkpoint(straight / "checkpoint.pt"), load_checkpoint(split / "checkpoint.pt")
    assert resumed.step == 5
    # The data cursor and random states came back: both runs end on the same place in the same
    # streams, and drew the same streams at the same steps.
    assert resumed.continuation["data"] == finished.continuation["data"]
    straight_records = [json.loads(line) for line in (straight / "log.jsonl").read_text().splitlines()]
    assert [r["stream_starts"] for r in records] == [r["stream_starts"] for r in straight_records]


def test_a_resume_after_a_crash_logs_each_step_once(synthetic_dir, tmp_path):
    run = tmp_path / "run"
    train(_args(synthetic_dir, run, 5, "--stop-at-step", "2"))
    # A crash after step 3 was logged but before its checkpoint.
    log_path = run / "log.jsonl"
    last = json.loads(log_path.read_text().splitlines()[-1])
    log_path.write_text(log_path.read_text() + json.dumps({**last, "step": 3}) + "\n")
    train(_args(synthetic_dir, run, 5, "--resume"))
    steps = [json.loads(line)["step"] for line in log_path.read_text().splitlines()]
    assert steps == [1, 2, 3, 4, 5]


def test_a_resume_after_a_crash_mid_write_drops_the_partial_line(synthetic_dir, tmp_path):
    run = tmp_path / "run"
    train(_args(synthetic_dir, run, 4, "--stop-at-step", "2"))
    log_path = run / "log.jsonl"
    log_path.write_text(log_path.read_text() + '{"step": 3, "tot')
    train(_args(synthetic_dir, run, 4, "--resume"))
    steps = [json.loads(line)["step"] for line in log_path.read_text().splitlines()]
    assert steps == [1, 2, 3, 4]


def test_a_corrupt_record_before_the_last_line_is_named(tmp_path):
    from evgate_train.train import drop_records_after

    log_path = tmp_path / "log.jsonl"
    log_path.write_text('{"step": 1}\nnot json\n{"step": 2}\n')
    with pytest.raises(TrainingSetupError, match=r"log.jsonl: line 2 is not a JSON record"):
        drop_records_after(log_path, 1)
    assert log_path.read_text() == '{"step": 1}\nnot json\n{"step": 2}\n'


def test_the_manifest_digest_ignores_wall_times_only(tmp_path):
    from evgate_train.train import manifest_digest

    def digest(wall_s, sha256):
        path = tmp_path / "manifest.json"
        path.write_text(json.dumps({
            "version": 5, "totals": {"events": 3, "wall-s": wall_s},
            "sequences": [{"name": "a", "wall-s": wall_s, "files": [{"path": "a.npz", "sha256": sha256}]}],
        }))
        return manifest_digest(path)

    assert digest(1.0, "ab") == digest(2.5, "ab")
    assert digest(1.0, "ab") != digest(1.0, "cd")


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


FULL_FRAME = Crop(left=0, top=0, height=48, width=96)


def test_flips_move_masks_flow_and_events_alike(synthetic_dir):
    sequence = load_sequence(synthetic_dir / "slide-0.npz")
    rng = np.random.default_rng(0)
    horizons = np.array([100.0, 40.0], np.float32)
    window = training_window(sequence, 2, FULL_FRAME, horizons, reference_input(sequence, 2), 10_000, rng)
    flipped = apply(window, Augmentation(True, True, True))
    np.testing.assert_array_equal(flipped.mask, window.mask[::-1, ::-1])
    np.testing.assert_array_equal(flipped.voxel, -window.voxel[:, ::-1, ::-1])
    np.testing.assert_array_equal(flipped.object_region, window.object_region[:, ::-1, ::-1])
    # The square slides right: after a horizontal flip its flow points left.
    moving = window.flow_valid & (np.abs(window.future_flow[:, 0]) > 0)
    assert moving.any() and (window.future_flow[:, 0][moving] > 0).all()
    assert (flipped.future_flow[:, 0][moving[:, ::-1, ::-1]] < 0).all()
    # Events stay on the (flipped) object: the share of future events inside the future mask
    # (events fire only on the square) is unchanged by the flip.
    assert _object_event_share(flipped) == pytest.approx(_object_event_share(window))
    assert flipped.future_events[0].on.tolist() == (~window.future_events[0].on).tolist()


def test_horizons_always_hold_the_scored_100_ms_and_distinct_grid_steps():
    rng = np.random.default_rng(1)
    for count in (1, 3, 10):
        horizons = draw_horizons(rng, count)
        assert horizons[0] == 100 and len(set(horizons.tolist())) == count
        assert all(h % 10 == 0 and 10 <= h <= 100 for h in horizons)
    for count in (0, 11):
        with pytest.raises(HorizonCountError, match=f"horizon count {count}: accepted 1 to 10"):
            draw_horizons(rng, count)


def test_targets_come_from_the_ground_truth_grid(synthetic_dir):
    from synthetic_sequence import SPEED_PX_PER_MS, object_mask

    sequence = load_sequence(synthetic_dir / "slide-0.npz")
    reference = 2
    t_ms = sequence.ref_ts[reference] / 1000
    horizons = np.array([100.0, 30.0, 5000.0], np.float32)
    window = training_window(sequence, reference, FULL_FRAME, horizons, reference_input(sequence, reference), 0, None)
    # A horizon beyond the grid is marked invalid rather than trained on an empty mask.
    assert window.future_valid.tolist() == [True, True, False]
    for k, horizon in enumerate(horizons[:2]):
        np.testing.assert_array_equal(window.future_mask[k], object_mask(t_ms + horizon))
        footprint = (object_mask(t_ms) | object_mask(t_ms + horizon)) > 0
        np.testing.assert_array_equal(window.footprint[k], footprint)
        # The object region covers the footprint and a ring around it, with the square's
        # displacement (rounded to whole pixels by the rasterised masks) as its flow.
        assert window.object_region[k][footprint].all() and window.object_region[k].sum() > footprint.sum()
        displacement = window.future_flow[k][:, window.object_region[k]]
        np.testing.assert_allclose(displacement[0], SPEED_PX_PER_MS * horizon, atol=1.0)
        np.testing.assert_allclose(displacement[1], 0.0, atol=1e-6)
        assert window.flow_valid[k][window.object_region[k]].all()
    assert window.future_events[0].x.size == 0


def test_a_crop_beyond_the_sensor_is_padded_with_background(synthetic_dir):
    sequence = load_sequence(synthetic_dir / "slide-0.npz")
    crop = Crop(left=0, top=0, height=64, width=112)
    window = training_window(sequence, 2, crop, draw_horizons(np.random.default_rng(0), 2), reference_input(sequence, 2), 0, None)
    assert window.voxel.shape == (2, 64, 112) and window.mask.shape == (64, 112)
    assert not window.voxel[:, 48:].any() and not window.mask[:, 96:].any() and not window.future_mask[:, 48:].any()


def test_stop_at_step_keeps_the_longer_schedule(synthetic_dir, tmp_path):
    from evgate_train.train import learning_rate

    run = tmp_path / "run"
    train(_args(synthetic_dir, run, 4, "--stop-at-step", "2"))
    records = [json.loads(line) for line in (run / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in records] == [1, 2]
    assert records[1]["lr"] == pytest.approx(learning_rate(1, 4, 1e-3, 1))
    assert load_checkpoint(run / "checkpoint.pt").step == 2


def test_channels_last_trains_the_same_arithmetic_in_another_layout(synthetic_dir, tmp_path):
    contiguous, channels_last = tmp_path / "contiguous", tmp_path / "channels-last"
    train(_args(synthetic_dir, contiguous, 3))
    train(_args(synthetic_dir, channels_last, 3, "--channels-last"))
    logged = [[json.loads(line) for line in (run / "log.jsonl").read_text().splitlines()] for run in (contiguous, channels_last)]
    for plain_record, channels_last_record in zip(*logged):
        assert channels_last_record["total"] == pytest.approx(plain_record["total"], rel=1e-3)
    # The weights really were in the other layout (kept by the saved tensors' strides) ...
    weights = torch.load(channels_last / "checkpoint.pt", map_location="cpu", weights_only=False)["weights"]
    reordered = [w for w in weights.values() if w.dim() == 4 and w.shape[1] > 1 and w.shape[-1] > 1]
    assert reordered and all(w.is_contiguous(memory_format=torch.channels_last) and not w.is_contiguous() for w in reordered)
    # ... and load as ordinary weights for evaluation and export.
    assert all(p.is_contiguous() for p in load_checkpoint(channels_last / "checkpoint.pt").network.parameters())


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


def test_time_budget_ends_the_run_and_saves_its_last_step(synthetic_dir, tmp_path):
    run = tmp_path / "run"
    train(_args(synthetic_dir, run, 1000, "--time-budget-s", "1e-9", "--checkpoint-every", "100"))
    assert not (run / "checkpoint.pt").exists()
    train(_args(synthetic_dir, tmp_path / "run2", 1000, "--time-budget-s", "3", "--checkpoint-every", "100"))
    records = [json.loads(line) for line in (tmp_path / "run2" / "log.jsonl").read_text().splitlines()]
    assert 0 < len(records) < 1000
    assert load_checkpoint(tmp_path / "run2" / "checkpoint.pt").step == len(records)


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


def test_input_normalisation_switches_at_init_from_and_stays_on_resume(synthetic_dir, tmp_path):
    source = tmp_path / "source"
    train(_args(synthetic_dir, source, 1))
    assert load_checkpoint(source / "checkpoint.pt").network.config.input_normalisation == "global"
    run = tmp_path / "local"
    train(_args(synthetic_dir, run, 2, "--init-from", str(source / "checkpoint.pt"), "--input-normalisation", "local",
                "--stop-at-step", "1"))
    assert load_checkpoint(run / "checkpoint.pt").network.config.input_normalisation == "local"
    # A resume without the flag keeps the checkpoint's network; one naming the other is refused.
    train(_args(synthetic_dir, run, 2, "--resume"))
    assert load_checkpoint(run / "checkpoint.pt").network.config.input_normalisation == "local"
    with pytest.raises(TrainingSetupError, match="--input-normalisation global: .* was trained with local"):
        train(_args(synthetic_dir, run, 3, "--resume", "--input-normalisation", "global"))


def test_convex_flow_upsampling_is_added_at_init_from_and_stays_on_resume(synthetic_dir, tmp_path):
    source = tmp_path / "source"
    train(_args(synthetic_dir, source, 1))
    run = tmp_path / "convex"
    train(_args(synthetic_dir, run, 2, "--init-from", str(source / "checkpoint.pt"), "--flow-upsampling", "convex",
                "--ema-decay", "0.9", "--stop-at-step", "1"))
    assert load_checkpoint(run / "checkpoint.pt").network.config.flow_upsampling == "convex"
    assert load_checkpoint(run / "ema.pt").network.config.flow_upsampling == "convex"
    train(_args(synthetic_dir, run, 2, "--resume"))
    assert load_checkpoint(run / "checkpoint.pt").step == 2
    with pytest.raises(TrainingSetupError, match="--flow-upsampling bilinear: .* upsamples its flow convex"):
        train(_args(synthetic_dir, run, 3, "--resume", "--flow-upsampling", "bilinear"))


def test_wider_decoder_and_encoder_and_3x3_gates_are_added_at_init_from_and_stay_on_resume(synthetic_dir, tmp_path):
    source = tmp_path / "source"
    train(_args(synthetic_dir, source, 1))
    run = tmp_path / "wide"
    train(_args(synthetic_dir, run, 2, "--init-from", str(source / "checkpoint.pt"), "--mask-decoder-width-factor", "2",
                "--first-spatial-gru-stage", "0", "--encoder-base-channels", "12", "--ema-decay", "0.9",
                "--stop-at-step", "1"))
    for name in ("checkpoint.pt", "ema.pt"):
        config = load_checkpoint(run / name).network.config
        assert (config.mask_decoder_width_factor, config.first_spatial_gru_stage, config.state_channels[0]) == (2, 0, 12)
    train(_args(synthetic_dir, run, 2, "--resume"))
    assert load_checkpoint(run / "checkpoint.pt").step == 2
    with pytest.raises(TrainingSetupError, match="--mask-decoder-width-factor 1: .* has mask decoder width factor 2"):
        train(_args(synthetic_dir, run, 3, "--resume", "--mask-decoder-width-factor", "1"))
    with pytest.raises(TrainingSetupError, match="--first-spatial-gru-stage 2: .* has first spatial gru stage 0"):
        train(_args(synthetic_dir, run, 3, "--resume", "--first-spatial-gru-stage", "2"))
    with pytest.raises(TrainingSetupError, match="--encoder-base-channels 8: .* has an encoder 12 channels wide"):
        train(_args(synthetic_dir, run, 3, "--resume", "--encoder-base-channels", "8"))


def test_the_weight_average_is_saved_resumed_and_averages(synthetic_dir, tmp_path):
    run = tmp_path / "run"
    train(_args(synthetic_dir, run, 2, "--ema-decay", "0.25", "--stop-at-step", "1"))
    first_raw, first_average = load_checkpoint(run / "checkpoint.pt"), load_checkpoint(run / "ema.pt")
    assert first_average.step == 1 and first_average.optimiser_state is None
    # The first update copies the weights it averages.
    for (name, raw), average in zip(first_raw.network.state_dict().items(), first_average.network.state_dict().values()):
        assert torch.equal(raw, average), name
    train(_args(synthetic_dir, run, 2, "--ema-decay", "0.25", "--resume"))
    second_raw, second_average = load_checkpoint(run / "checkpoint.pt"), load_checkpoint(run / "ema.pt")
    assert second_average.step == 2
    moved = 0
    for name, raw in second_raw.network.named_parameters():
        expected = 0.25 * first_raw.network.state_dict()[name] + 0.75 * raw.detach()
        torch.testing.assert_close(second_average.network.state_dict()[name], expected, msg=name)
        moved += int(not torch.equal(raw.detach(), first_raw.network.state_dict()[name]))
    assert moved > 0


def test_without_a_decay_no_average_is_kept(synthetic_dir, tmp_path):
    train(_args(synthetic_dir, tmp_path / "run", 1))
    assert not (tmp_path / "run" / "ema.pt").exists()


@pytest.mark.parametrize("decay", ["-0.1", "1.0"])
def test_an_ema_decay_outside_its_range_is_refused(synthetic_dir, tmp_path, decay):
    with pytest.raises(TrainingSetupError, match=f"--ema-decay {float(decay)}: must be 0"):
        train(_args(synthetic_dir, tmp_path / "run", 1, "--ema-decay", decay))


def test_a_time_budget_drives_the_decay_when_it_is_further_along_than_the_steps():
    from evgate_train.train import learning_rate

    assert learning_rate(10, 1000, 1.0, 5) == pytest.approx(learning_rate(10, 1000, 1.0, 5, time_spent=0.001))
    assert learning_rate(10, 1000, 1.0, 5, time_spent=0.5) == pytest.approx(0.55)
    assert learning_rate(10, 1000, 1.0, 5, time_spent=1.0) == pytest.approx(0.1)
    assert learning_rate(999, 1000, 1.0, 5, time_spent=0.0) == pytest.approx(0.1, abs=1e-3)
    # Warm-up runs on steps whatever the time spent.
    assert learning_rate(1, 1000, 1.0, 5, time_spent=0.9) == pytest.approx(0.4)


@pytest.mark.parametrize(
    "flag, value", [("--fired-pixel-weight", "4"), ("--small-object-area", "4000"), ("--focal-gamma", "2")]
)
def test_each_mask_loss_option_changes_the_mask_loss(synthetic_dir, tmp_path, flag, value):
    uniform = _first_mask_loss(synthetic_dir, tmp_path / "uniform")
    assert uniform != pytest.approx(_first_mask_loss(synthetic_dir, tmp_path / "emphasised", flag, value))


@pytest.mark.parametrize("flag", ["--fired-pixel-weight", "--small-object-area", "--focal-gamma"])
def test_a_negative_mask_loss_option_is_refused(synthetic_dir, tmp_path, flag):
    with pytest.raises(TrainingSetupError, match=f"{flag} -1.0: must be 0"):
        train(_args(synthetic_dir, tmp_path / "run", 2, flag, "-1"))
