"""Latency of a checkpoint's network in PyTorch on a device (a GPU where ONNX Runtime's CUDA
provider cannot be installed): the same streaming call as `latency`, timed with the device
synchronised around each window.

    python -m evgate_train.torch_latency --checkpoint runs/L/checkpoint.pt --device cuda \
        --inputs 346x260,640x480 --horizons 1,8 --output runs/L-cuda-latency.json

Eager PyTorch, float32 (TF32 convolutions and matrix products on CUDA unless --no-tf32), batch 1,
zero states at the start then the returned states fed back. Median, p90 and mean per input
size and K.
"""

import argparse
import platform
import sys
import time
from pathlib import Path

import torch

from .checkpoint import load_checkpoint
from .timings import print_and_save, timing_summary
from .network import SuppressionNetwork
from .voxel import padded


class LatencySetupError(ValueError):
    """An input size or horizon list that cannot be timed."""


def parse_inputs(text: str) -> list[tuple[int, int]]:
    sizes = []
    for item in text.split(","):
        width, separator, height = item.partition("x")
        if not separator or not width.isdigit() or not height.isdigit():
            raise LatencySetupError(f"--inputs {item!r}: expected WIDTHxHEIGHT, e.g. 346x260")
        sizes.append((int(width), int(height)))
    return sizes


@torch.no_grad()
def measure(network: SuppressionNetwork, device: torch.device, width: int, height: int, horizons: int,
            runs: int, warmup: int) -> dict:
    generator = torch.Generator(device="cpu").manual_seed(0)
    padded_height, padded_width = padded(height), padded(width)
    states = network.initial_states(1, padded_height, padded_width, device)
    horizon_values = torch.linspace(100.0 / horizons, 100.0, horizons, device=device)[None]
    timings = []
    for run in range(warmup + runs):
        values = torch.randn(1, 2, padded_height, padded_width, generator=generator)
        voxel = torch.where(torch.rand(values.shape, generator=generator) < 0.1, values, 0.0).to(device)
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        started = time.perf_counter()
        out = network(voxel, horizon_values, states, warp_resolution="half")
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        elapsed = time.perf_counter() - started
        states = out.states
        if run >= warmup:
            timings.append(elapsed * 1000.0)
    return {"input": f"{width}x{height}", "horizons": horizons, **timing_summary(timings)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--checkpoint", type=Path, required=True, help="training checkpoint (.pt)")
    parser.add_argument("--device", default="cuda", help="torch device: cuda or cpu")
    parser.add_argument("--inputs", default="346x260,640x480", help="comma-separated WIDTHxHEIGHT sensor sizes")
    parser.add_argument("--horizons", default="1,8", help="comma-separated K values to time")
    parser.add_argument("--runs", type=int, default=100, help="timed windows per setting")
    parser.add_argument("--warmup", type=int, default=20, help="untimed windows first")
    parser.add_argument("--no-tf32", action="store_true", help="full float32 convolutions and matrix products")
    parser.add_argument("--output", type=Path, help="also write the result as JSON here")
    args = parser.parse_args(argv)
    device = torch.device(args.device)
    if device.type == "cuda":
        if not torch.cuda.is_available():
            raise LatencySetupError(f"--device {args.device}: torch sees no CUDA device")
        torch.backends.cudnn.benchmark = True
        torch.backends.cuda.matmul.allow_tf32 = not args.no_tf32
        torch.backends.cudnn.allow_tf32 = not args.no_tf32
    checkpoint = load_checkpoint(args.checkpoint)
    network = checkpoint.network.to(device).eval()
    result = {
        "checkpoint": str(args.checkpoint),
        "size": network.config.size,
        "steps": checkpoint.step,
        "device": torch.cuda.get_device_name(device) if device.type == "cuda" else platform.processor(),
        "torch": torch.__version__,
        "precision": "float32" if args.no_tf32 or device.type != "cuda" else "float32 with TF32",
        "warp_resolution": "half",
        "results": [
            measure(network, device, width, height, int(k), args.runs, args.warmup)
            for width, height in parse_inputs(args.inputs)
            for k in args.horizons.split(",")
        ],
    }
    print_and_save(result, args.output)
    return 0


if __name__ == "__main__":
    sys.exit(main())
