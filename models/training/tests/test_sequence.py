import numpy as np
import pytest

from evgate_train.sequence import SequenceFormatError, load_sequence


def test_reads_the_synthetic_sequence(synthetic_dir):
    sequence = load_sequence(synthetic_dir / "slide-0.npz")
    assert (sequence.width, sequence.height) == (96, 48)
    assert sequence.preset == "synthetic-test"
    assert sequence.grid_index(int(sequence.ref_ts[0])) is not None
    window = sequence.event_range(50_000, 100_000)
    assert (sequence.events_t[window] >= 50_000).all() and (sequence.events_t[window] < 100_000).all()


def test_missing_array_is_named(tmp_path, synthetic_dir):
    arrays = dict(np.load(synthetic_dir / "slide-0.npz"))
    del arrays["future_flow"]
    path = tmp_path / "broken.npz"
    np.savez(path, **arrays)
    with pytest.raises(SequenceFormatError, match="broken.npz: missing array 'future_flow'"):
        load_sequence(path)


def test_wrong_dtype_is_named(tmp_path, synthetic_dir):
    arrays = dict(np.load(synthetic_dir / "slide-0.npz"))
    arrays["events_t"] = arrays["events_t"].astype(np.float64)
    path = tmp_path / "float-times.npz"
    np.savez(path, **arrays)
    with pytest.raises(SequenceFormatError, match="'events_t' is float64 with 1 dimensions, expected int64"):
        load_sequence(path)


def test_not_a_zip_is_reported(tmp_path):
    path = tmp_path / "garbage.npz"
    path.write_bytes(b"not a zip")
    with pytest.raises(SequenceFormatError, match="garbage.npz: not a readable .npz"):
        load_sequence(path)


def test_manifest_lists_every_sequence_with_its_hash(synthetic_dir, tmp_path):
    from evgate_train.manifest import build_manifest, file_sha256

    manifest = build_manifest(synthetic_dir)
    assert [e["path"] for e in manifest["sequences"]] == ["slide-0.npz", "slide-1.npz"]
    assert manifest["sequences"][1]["seed"] == 1
    assert manifest["sequences"][0]["sha256"] == file_sha256(synthetic_dir / "slide-0.npz")
