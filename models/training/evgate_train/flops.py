"""Parameters and compute of every model size at the sensor sizes of interest.

    python -m evgate_train.flops --output runs/flops.json
    python -m evgate_train.flops --sizes S --first-spatial-gru-stage 0   # S with 3x3 gates everywhere

Counts with torch's FlopCounterMode (convolutions, matrix products incl. attention; one
multiply-add = 2 FLOPs) for one window and K = 1 horizon. Inputs are padded to multiples of 16
as the runtime pads them (346x260 -> 352x272).
"""

import argparse
import json
import sys
from pathlib import Path

import torch
from torch.utils.flop_counter import FlopCounterMode

from .network import FIRST_SPATIAL_GRU_STAGE, NetworkConfig, SuppressionNetwork, parameter_count
from .sizes import BASE_CHANNELS, STAGES
from .voxel import padded

SENSORS = ((346, 260), (640, 480))


def gflops(network: SuppressionNetwork, width: int, height: int, horizons: int) -> float:
    height, width = padded(height), padded(width)
    voxel = torch.zeros(1, 2, height, width)
    with torch.no_grad(), FlopCounterMode(display=False) as counter:
        network(voxel, torch.full((1, horizons), 50.0), network.initial_states(1, height, width))
    return counter.get_total_flops() / 1e9


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--horizons", type=int, default=1, help="forecast horizons per window (K)")
    parser.add_argument(
        "--sizes",
        type=lambda text: text.split(","),
        default=list(BASE_CHANNELS),
        help=f"comma-separated model sizes to count (default: all of {', '.join(BASE_CHANNELS)})",
    )
    parser.add_argument(
        "--first-spatial-gru-stage",
        type=int,
        choices=range(STAGES + 1),
        default=FIRST_SPATIAL_GRU_STAGE,
        help=f"first encoder stage whose ConvGRU has 3x3 gates, 0 to {STAGES} (default {FIRST_SPATIAL_GRU_STAGE})",
    )
    parser.add_argument("--output", type=Path, help="also write the table as JSON here")
    args = parser.parse_args(argv)
    unknown = [size for size in args.sizes if size not in BASE_CHANNELS]
    if unknown:
        parser.error(f"--sizes: unknown size {unknown[0]!r}; accepted: {', '.join(BASE_CHANNELS)}")
    rows = []
    for size in args.sizes:
        config = NetworkConfig(size=size, first_spatial_gru_stage=args.first_spatial_gru_stage)
        network = SuppressionNetwork(config).eval()
        row = {
            "size": size,
            "first-spatial-gru-stage": args.first_spatial_gru_stage,
            "parameters": parameter_count(network),
        }
        for width, height in SENSORS:
            row[f"gflops-{width}x{height}"] = round(gflops(network, width, height, args.horizons), 3)
        rows.append(row)
        print(json.dumps(row))
    if args.output:
        args.output.parent.mkdir(parents=True, exist_ok=True)
        args.output.write_text(json.dumps({"horizons": args.horizons, "models": rows}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
