"""Exports a trained network to ONNX following docs/model-contract.md.

    python -m evgate_train.export --checkpoint runs/S/checkpoint.pt --output ../evgate-S.onnx
    python -m evgate_train.export --size XS --untrained --output /tmp/evgate-XS-untrained.onnx

The future mask logits are warped at half resolution by default (`--warp-resolution`,
network.WARP_RESOLUTIONS): the same weights, a quarter of the sampling work per horizon.
"""

import argparse
import logging
import math
import sys
from pathlib import Path

import onnx
import torch
from torch import nn

from .checkpoint import load_checkpoint
from .export_network import export_forward
from .graph_rewrite import split_concatenated_convolutions
from .network import VOXEL_BINS, WARP_RESOLUTIONS, NetworkConfig, SuppressionNetwork, check_input_size, check_warp_resolution
from .voxel import WINDOW_US

MAX_HORIZON_MS = 100
OPSET = 18
# The largest evgate.keep-dilation-px the runtime accepts (evgate-model's MAX_KEEP_DILATION_PX).
MAX_KEEP_DILATION_PX = 16
STATE_COUNT = 4
INPUT_NAMES = ["voxel", "horizons_ms"] + [f"state_{i}" for i in range(STATE_COUNT)]
OUTPUT_NAMES = ["mask_logits", "future_mask_logits", "future_flow"] + [f"new_state_{i}" for i in range(STATE_COUNT)]

log = logging.getLogger("evgate_train.export")


class RuntimeInputError(ValueError):
    """A network whose input the runtime (evgate-core) does not build."""


def check_runtime_input(config: NetworkConfig) -> None:
    if config.voxel_bins != VOXEL_BINS or config.motion_compensated_channel:
        raise RuntimeInputError(
            f"the network takes {config.voxel_bins} voxel bins"
            + (" and the motion-compensated channel" if config.motion_compensated_channel else "")
            + f"; the runtime builds only the {VOXEL_BINS}-bin voxel grid (docs/model-contract.md), so it cannot be exported"
        )


class ContractWrapper(nn.Module):
    """The contract's flat signature: one stream (batch 1), horizons [K], states as four inputs."""

    def __init__(self, network: SuppressionNetwork, warp_resolution: str):
        super().__init__()
        self.network = network
        self.warp_resolution = check_warp_resolution(warp_resolution)

    def forward(self, voxel, horizons_ms, state_0, state_1, state_2, state_3):
        states = [state_0, state_1, state_2, state_3]
        # The flow leaves at the flow decoder's resolution (metadata evgate.flow-stride): nothing
        # in the graph needs it at full resolution, and upsampling 2K planes there cost more
        # than the warp itself on CPU.
        return export_forward(self.network, voxel, horizons_ms, states, self.warp_resolution)


def example_inputs(network: SuppressionNetwork, height: int, width: int, horizons: int = 2) -> tuple[torch.Tensor, ...]:
    generator = torch.Generator().manual_seed(0)
    voxel = torch.randn(1, 2, height, width, generator=generator)
    horizons_ms = torch.linspace(MAX_HORIZON_MS / horizons, MAX_HORIZON_MS, horizons)
    return (voxel, horizons_ms, *network.initial_states(1, height, width))


def export(
    network: SuppressionNetwork,
    path: Path,
    height: int,
    width: int,
    manifest_sha256: str,
    train_steps: int,
    warp_resolution: str = "half",
    threshold_logit: float = 0.0,
    keep_dilation_px: int = 0,
    keep_threshold_logit: float | None = None,
) -> None:
    check_input_size(height, width)
    check_runtime_input(network.config)
    # The wrapper must be in eval mode too: the exporter restores the wrapper's mode afterwards,
    # recursively, and a network left in training mode would use batch statistics.
    wrapper = ContractWrapper(network, warp_resolution).eval()
    inputs = example_inputs(network, height, width)
    horizon_axis = {"horizons_ms": {0: "K"}, "future_mask_logits": {1: "K"}, "future_flow": {1: "K"}}
    path.parent.mkdir(parents=True, exist_ok=True)
    with torch.no_grad():
        torch.onnx.export(
            wrapper,
            inputs,
            str(path),
            input_names=INPUT_NAMES,
            output_names=OUTPUT_NAMES,
            dynamic_axes=horizon_axis,
            opset_version=OPSET,
            dynamo=False,
        )
    model = onnx.load(str(path))
    split = split_concatenated_convolutions(model)
    log.info("split %d convolutions of concatenated inputs", split)
    config = network.config
    metadata = {
        "evgate.model-size": config.size,
        "evgate.base-channels": str(config.base),
        "evgate.state-channels": ",".join(str(c) for c in config.state_channels),
        "evgate.bins": str(VOXEL_BINS),
        "evgate.window-ms": str(WINDOW_US // 1000),
        "evgate.input-height": str(height),
        "evgate.input-width": str(width),
        "evgate.max-horizon-ms": str(MAX_HORIZON_MS),
        "evgate.atc": config.time_conditioning,
        "evgate.train-manifest-sha256": manifest_sha256,
        "evgate.train-steps": str(train_steps),
        "evgate.warp-resolution": warp_resolution,
        "evgate.flow-stride": str(network.flow_stride),
        "evgate.flow-upsampling": config.flow_upsampling,
        "evgate.mask-decoder-width": str(config.mask_decoder_width),
        "evgate.first-spatial-gru-stage": str(config.first_spatial_gru_stage),
        "evgate.threshold-logit": repr(float(threshold_logit)),
        "evgate.keep-threshold-logit": repr(
            float(threshold_logit if keep_threshold_logit is None else keep_threshold_logit)
        ),
        "evgate.keep-dilation-px": str(keep_dilation_px),
    }
    del model.metadata_props[:]
    for key, value in metadata.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.checker.check_model(model)
    onnx.save(model, str(path))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--checkpoint", type=Path, help="training checkpoint to export")
    source.add_argument("--untrained", action="store_true", help="export freshly initialised weights (runtime tests)")
    parser.add_argument("--size", default="S", help="model size for --untrained: XS, S, M or L")
    parser.add_argument(
        "--time-conditioning", default="position-aware", help="for --untrained: position-aware, reference or none"
    )
    parser.add_argument("--height", type=int, default=272, help="padded input height (multiple of 16)")
    parser.add_argument("--width", type=int, default=352, help="padded input width (multiple of 16)")
    parser.add_argument("--output", type=Path, required=True, help="where to write the .onnx file")
    parser.add_argument(
        "--train-steps",
        type=int,
        help="optimiser steps to record instead of the checkpoint's own count: a run started with "
        "--init-from counts from 0, so a fine-tuned chain records the sum of its runs' steps",
    )
    parser.add_argument(
        "--warp-resolution",
        choices=WARP_RESOLUTIONS,
        default="half",
        help="resolution the future mask logits are warped at: half (the mask decoder's, cheaper on CPU) or "
        "full (the training path, as exports before the half-resolution path)",
    )
    parser.add_argument(
        "--threshold-logit",
        type=float,
        default=0.0,
        help="mask threshold written as evgate.threshold-logit, which evgate-infer and evgate eval apply "
        "(choose it on val with evgate_train.calibrate)",
    )
    parser.add_argument(
        "--keep-threshold-logit",
        type=float,
        help="written as evgate.keep-threshold-logit: a horizon's events are kept where its forecast logits, "
        "dilated by --keep-dilation-px, exceed it (default: --threshold-logit; choose both with calibrate "
        "--dilations)",
    )
    parser.add_argument(
        "--keep-dilation-px",
        type=int,
        default=0,
        help="written as evgate.keep-dilation-px: the radius of the square over which evgate-infer and evgate eval "
        f"take the maximum of each forecast's logits to draw its keep region (0 to {MAX_KEEP_DILATION_PX})",
    )
    args = parser.parse_args(argv)
    if not 0 <= args.keep_dilation_px <= MAX_KEEP_DILATION_PX:
        parser.error(f"--keep-dilation-px {args.keep_dilation_px}: expected 0 to {MAX_KEEP_DILATION_PX} pixels")
    for flag, value in (("--threshold-logit", args.threshold_logit), ("--keep-threshold-logit", args.keep_threshold_logit)):
        if value is not None and not math.isfinite(value):
            parser.error(f"{flag} {value}: expected a finite number")
    if args.train_steps is not None and args.train_steps < 0:
        parser.error(f"--train-steps {args.train_steps}: expected a non-negative number of steps")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    if args.checkpoint:
        checkpoint = load_checkpoint(args.checkpoint)
        network = checkpoint.network
        manifest = checkpoint.manifest_sha256
        steps = checkpoint.step if args.train_steps is None else args.train_steps
    else:
        torch.manual_seed(0)
        network = SuppressionNetwork(NetworkConfig(size=args.size, time_conditioning=args.time_conditioning))
        manifest, steps = "untrained", 0
    export(
        network,
        args.output,
        args.height,
        args.width,
        manifest,
        steps,
        args.warp_resolution,
        args.threshold_logit,
        args.keep_dilation_px,
        args.keep_threshold_logit,
    )
    log.info(
        "wrote %s (%s, %dx%d, %d steps, warp at %s resolution)",
        args.output, network.config.size, args.width, args.height, steps, args.warp_resolution,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
