import sys
from pathlib import Path

import pytest
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from synthetic_sequence import write_sequence  # noqa: E402

# Two shared cores: one thread avoids OpenMP workers spinning against each other.
torch.set_num_threads(1)


@pytest.fixture(scope="session")
def synthetic_dir(tmp_path_factory) -> Path:
    directory = tmp_path_factory.mktemp("sequences")
    write_sequence(directory / "slide-0.npz", seed=0)
    write_sequence(directory / "slide-1.npz", seed=1)
    (directory / "manifest.json").write_text('{"sequences": ["slide-0.npz", "slide-1.npz"]}')
    return directory
