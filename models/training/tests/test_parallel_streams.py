import json

import numpy as np
import pytest
import torch

from evgate_train.checkpoint import load_checkpoint
from evgate_train.jitter import JitterRanges
from evgate_train.parallel_streams import ShardedStreams, shard_seed
from evgate_train.streams import StreamSampler, StreamSetupError
from evgate_train.train import build_parser, train


def _arguments(synthetic_dir, streams):
    paths = sorted(synthetic_dir.rglob("*.npz"))
    return dict(paths=paths, streams=streams, windows_per_step=2, crop_height=48, crop_width=96, horizons=3,
                max_events=0, augment=True, seed=5, jitter=JitterRanges())


def _assert_same_step(got, expected):
    np.testing.assert_array_equal(got.starts, expected.starts)
    for got_batch, expected_batch in zip(got.windows, expected.windows, strict=True):
        for name in ("voxel", "mask", "future_mask", "future_flow", "flow_valid", "object_region", "horizons_ms"):
            torch.testing.assert_close(getattr(got_batch, name), getattr(expected_batch, name), rtol=0, atol=0)


def test_the_workers_play_the_streams_of_in_process_samplers_of_their_seeds(synthetic_dir):
    arguments = _arguments(synthetic_dir, streams=4)
    sharded = ShardedStreams(2, **arguments)
    shards = [StreamSampler(**{**arguments, "streams": 2, "seed": shard_seed(5, shard)}) for shard in range(2)]
    for _ in range(5):
        got = sharded.step()
        parts = [shard.step() for shard in shards]
        assert got.windows[0].voxel.shape[0] == 4
        assert len(got.windows[0].future_events) == 4
        np.testing.assert_array_equal(got.starts, np.concatenate([part.starts for part in parts]))
        for window in range(2):
            for name in ("voxel", "mask", "future_flow", "object_region"):
                torch.testing.assert_close(
                    getattr(got.windows[window], name),
                    torch.cat([getattr(part.windows[window], name) for part in parts]),
                    rtol=0,
                    atol=0,
                )
    assert sharded.state_dict() == {"shards": [shard.state_dict() for shard in shards]}


def test_a_cursor_continues_every_workers_stream(synthetic_dir):
    arguments = _arguments(synthetic_dir, streams=2)
    first = ShardedStreams(2, **arguments)
    for _ in range(3):
        first.step()
    cursor = first.state_dict()
    expected = first.step()
    second = ShardedStreams(2, **arguments)
    second.load_state_dict(json.loads(json.dumps(cursor)))
    _assert_same_step(second.step(), expected)
    # The shards in this process replay what the workers played, for the recurrent states.
    assert len(second.played_voxels(1)) == second.shards[1].cursors[0].next_reference - second.shards[1].cursors[0].first_reference


def test_streams_that_do_not_split_evenly_are_refused(synthetic_dir):
    with pytest.raises(StreamSetupError, match="3 streams over 2 data workers"):
        ShardedStreams(2, **_arguments(synthetic_dir, streams=3))


def test_a_cursor_of_another_worker_count_is_refused(synthetic_dir):
    arguments = _arguments(synthetic_dir, streams=2)
    in_process = StreamSampler(**arguments)
    in_process.step()
    with pytest.raises(StreamSetupError, match="resume with the same --data-workers"):
        ShardedStreams(2, **arguments).load_state_dict(in_process.state_dict())
    with pytest.raises(StreamSetupError, match="saved by 2 data workers"):
        StreamSampler(**arguments).load_state_dict(ShardedStreams(2, **arguments).state_dict())


def test_training_with_data_workers_resumes_their_streams(synthetic_dir, tmp_path):
    def args(run_dir, *extra):
        return build_parser().parse_args(
            [
                "--data", str(synthetic_dir), "--manifest", str(synthetic_dir / "manifest.json"),
                "--run-dir", str(run_dir), "--size", "XS", "--steps", "4", "--streams", "2", "--data-workers", "2",
                "--windows-per-step", "2", "--crop", "48x96", "--checkpoint-every", "1", "--warmup", "1", *extra,
            ]
        )

    straight, split = tmp_path / "straight", tmp_path / "split"
    train(args(straight))
    train(args(split, "--stop-at-step", "2"))
    train(args(split, "--resume"))
    finished, resumed = load_checkpoint(straight / "checkpoint.pt"), load_checkpoint(split / "checkpoint.pt")
    assert resumed.step == finished.step == 4
    assert len(resumed.continuation["data"]["shards"]) == 2
    assert resumed.continuation["data"] == finished.continuation["data"]
    records = [json.loads(line) for line in (split / "log.jsonl").read_text().splitlines()]
    straight_records = [json.loads(line) for line in (straight / "log.jsonl").read_text().splitlines()]
    assert [r["stream_starts"] for r in records] == [r["stream_starts"] for r in straight_records]


def test_the_open_file_limit_is_raised_for_the_tensors_in_flight():
    import resource

    from evgate_train.parallel_streams import allow_open_files

    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (256, hard))
    try:
        allow_open_files(512)
        assert resource.getrlimit(resource.RLIMIT_NOFILE)[0] == 512
        allow_open_files(300)  # never lowered
        assert resource.getrlimit(resource.RLIMIT_NOFILE)[0] == 512
    finally:
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
