"""An exported .onnx network behind the PyTorch network's evaluation interface, so that
evaluate.py scores the very file the Rust runtime ships (graph rewrites included) with the
same streaming and metrics as a checkpoint.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import onnx
import onnxruntime
import torch
from google.protobuf.message import DecodeError

from .checkpoint import Checkpoint


class ExportError(ValueError):
    """An .onnx file that cannot be loaded, or a stream whose size the export does not take."""


@dataclass(frozen=True)
class ExportConfig:
    size: str
    time_conditioning: str


@dataclass
class ExportOutput:
    mask_logits: torch.Tensor  # [1, 1, H, W]
    future_mask_logits: torch.Tensor  # [1, K, H, W]
    states: list[np.ndarray]


class OnnxNetwork:
    def __init__(self, path: Path, threads: int):
        try:
            metadata = {p.key: p.value for p in onnx.load(str(path), load_external_data=False).metadata_props}
            options = onnxruntime.SessionOptions()
            options.intra_op_num_threads = threads
            options.inter_op_num_threads = 1
            self.session = onnxruntime.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
        except (OSError, DecodeError, RuntimeError) as error:
            raise ExportError(f"{path}: cannot load the export: {error}") from error
        missing = [key for key in ("evgate.model-size", "evgate.atc", "evgate.train-steps") if key not in metadata]
        if missing:
            raise ExportError(f"{path}: metadata lacks {', '.join(missing)} (docs/model-contract.md)")
        self.path = path
        self.metadata = metadata
        self.config = ExportConfig(size=metadata["evgate.model-size"], time_conditioning=metadata["evgate.atc"])
        # Exports made before the key existed warped at full resolution.
        self.warp_resolution = metadata.get("evgate.warp-resolution", "full")
        self.state_shapes = [tuple(i.shape) for i in self.session.get_inputs() if i.name.startswith("state_")]
        self.input_size = tuple(self.session.get_inputs()[0].shape[2:])

    def eval(self) -> "OnnxNetwork":
        return self

    def initial_states(self, batch: int, height: int, width: int) -> list[np.ndarray]:
        if batch != 1 or (height, width) != self.input_size:
            raise ExportError(
                f"{self.path}: exported for one stream of {self.input_size[1]}x{self.input_size[0]} (width x height); "
                f"asked for {batch} of {width}x{height}"
            )
        return [np.zeros(shape, np.float32) for shape in self.state_shapes]

    def __call__(
        self, voxel: torch.Tensor, horizons_ms: torch.Tensor, states: list[np.ndarray], warp_resolution: str
    ) -> ExportOutput:
        """voxel [1, 2, H, W], horizons_ms [1, K]; `warp_resolution` must be the one the graph
        was exported with (`self.warp_resolution`): an export cannot change it."""
        if warp_resolution != self.warp_resolution:
            raise ExportError(
                f"{self.path}: exported with warp resolution {self.warp_resolution}; {warp_resolution} was asked for"
            )
        feeds = {"voxel": voxel.numpy(), "horizons_ms": horizons_ms[0].numpy().astype(np.float32)}
        feeds.update({f"state_{i}": state for i, state in enumerate(states)})
        outputs = self.session.run(None, feeds)
        return ExportOutput(
            mask_logits=torch.from_numpy(outputs[0]),
            future_mask_logits=torch.from_numpy(outputs[1]),
            states=outputs[3:],
        )


def load_export(path: Path, threads: int) -> Checkpoint:
    """The export as a `Checkpoint` whose network runs through ONNX Runtime."""
    network = OnnxNetwork(path, threads)
    return Checkpoint(
        network=network,
        step=int(network.metadata["evgate.train-steps"]),
        manifest_sha256=network.metadata.get("evgate.train-manifest-sha256", ""),
        optimiser_state=None,
        train_config={},
        continuation=None,
    )
