"""How closely exports of a checkpoint follow it in PyTorch on recorded windows, through ONNX
Runtime, with the recurrent state carried (the parity test does the same on a tiny random model).

    python -m evgate_train.export_parity --checkpoint runs/S2-c160/checkpoint-step2500.pt \\
        --data ../../data/suite-v4/val --export previous=/tmp/evgate-S-before.onnx --export new=../evgate-S.onnx \\
        --output ../../evidence/models/latency/export-rewrite/S-parity-val-v4.json

Per export and output: the largest absolute difference and the largest ratio to the parity
tolerance (1e-4 + 1e-4 |PyTorch|); for the future mask logits also how many values exceed
that tolerance and how many change sign (the suppression decision). Sequences whose sensor
does not pad to the exports' input size are skipped.
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import onnx
import onnxruntime
import torch
from tqdm import tqdm

from .checkpoint import load_checkpoint
from .export import OUTPUT_NAMES
from .sequence import load_sequence
from .voxel import voxel_grid

TOLERANCE = 1e-4
HORIZON_COUNT = 8
MAX_HORIZON_MS = 100.0


class ParitySetupError(ValueError):
    """An export spec that is not NAME=FILE.onnx naming an existing file."""


def parse_export(spec: str) -> tuple[str, Path]:
    name, separator, path = spec.partition("=")
    if not separator or not name or not Path(path).is_file():
        raise ParitySetupError(f"--export {spec!r}: expected NAME=FILE.onnx naming an existing file")
    return name, Path(path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--checkpoint", type=Path, required=True, help="training checkpoint the exports were made from")
    parser.add_argument("--data", type=Path, required=True, help="directory searched recursively for .npz sequences")
    parser.add_argument("--export", action="append", required=True, help="NAME=FILE.onnx; repeatable")
    parser.add_argument("--sequences", type=int, default=3, help="sequences used (the first that fit, sorted by path)")
    parser.add_argument("--windows", type=int, default=8, help="consecutive 50 ms windows per sequence")
    parser.add_argument("--skip-windows", type=int, default=5, help="windows skipped at each sequence's start")
    parser.add_argument("--threads", type=int, default=2, help="torch and ONNX Runtime CPU threads")
    parser.add_argument("--output", type=Path, required=True, help="JSON report path")
    args = parser.parse_args(argv)
    try:
        exports = [parse_export(spec) for spec in args.export]
    except ParitySetupError as error:
        parser.error(str(error))
    torch.set_num_threads(args.threads)
    network = load_checkpoint(args.checkpoint).network.eval()
    sessions, warp_resolutions, input_sizes = {}, {}, set()
    for name, path in exports:
        options = onnxruntime.SessionOptions()
        options.intra_op_num_threads = args.threads
        sessions[name] = onnxruntime.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
        metadata = {p.key: p.value for p in onnx.load(str(path), load_external_data=False).metadata_props}
        warp_resolutions[name] = metadata.get("evgate.warp-resolution", "full")
        input_sizes.add(tuple(sessions[name].get_inputs()[0].shape[2:]))
    if len(input_sizes) != 1 or len(set(warp_resolutions.values())) != 1:
        parser.error(
            f"--export: the exports differ in input size {sorted(input_sizes)} or warp resolution {warp_resolutions}"
        )
    (height, width), warp_resolution = input_sizes.pop(), warp_resolutions[exports[0][0]]
    horizons = np.linspace(MAX_HORIZON_MS / HORIZON_COUNT, MAX_HORIZON_MS, HORIZON_COUNT).astype(np.float32)

    largest = {name: dict.fromkeys(OUTPUT_NAMES, 0.0) for name in sessions}
    tolerance_ratio = {name: dict.fromkeys(OUTPUT_NAMES, 0.0) for name in sessions}
    over_tolerance = dict.fromkeys(sessions, 0)
    sign_changes = dict.fromkeys(sessions, 0)
    future_values = 0
    used = []
    for path in sorted(args.data.rglob("*.npz")):
        if len(used) == args.sequences:
            break
        sequence = load_sequence(path)
        if sequence.height > height or sequence.width > width:
            continue
        used.append(str(path))
        states = network.initial_states(1, height, width)
        references = sequence.ref_ts[args.skip_windows : args.skip_windows + args.windows]
        for reference in tqdm(references, desc=path.parent.name, unit="window", leave=False):
            t_end = int(reference)
            window = sequence.event_range(t_end - 50_000, t_end + 1)
            grid = voxel_grid(
                sequence.events_t[window], sequence.events_x[window], sequence.events_y[window],
                sequence.events_on[window], t_end, sequence.width, sequence.height,
            )
            voxel = np.zeros((1, 2, height, width), np.float32)
            voxel[0, :, : grid.shape[1], : grid.shape[2]] = grid
            with torch.no_grad():
                out = network(torch.from_numpy(voxel), torch.from_numpy(horizons)[None], states, warp_resolution)
            expected = [t.numpy() for t in (out.mask_logits, out.future_mask_logits, out.coarse_flow, *out.states)]
            feeds = {"voxel": voxel, "horizons_ms": horizons}
            feeds.update({f"state_{i}": state.numpy() for i, state in enumerate(states)})
            for name, session in sessions.items():
                for output, got, want in zip(OUTPUT_NAMES, session.run(OUTPUT_NAMES, feeds), expected):
                    difference = np.abs(got - want)
                    allowed = TOLERANCE + TOLERANCE * np.abs(want)
                    largest[name][output] = max(largest[name][output], float(difference.max()))
                    ratio = float((difference / allowed).max())
                    tolerance_ratio[name][output] = max(tolerance_ratio[name][output], ratio)
                    if output == "future_mask_logits":
                        over_tolerance[name] += int((difference > allowed).sum())
                        sign_changes[name] += int(((got > 0) != (want > 0)).sum())
            future_values += expected[1].size
            states = out.states
    if not used:
        parser.error(
            f"--data {args.data}: no .npz sequence fits the exports' input of {width}x{height} (width x height)"
        )
    report = {
        "checkpoint": str(args.checkpoint),
        "exports": {name: str(path) for name, path in exports},
        "sequences": used,
        "windows_per_sequence": args.windows,
        "horizons_ms": horizons.tolist(),
        "future_mask_values": future_values,
        "future_mask_values_over_tolerance": over_tolerance,
        "future_mask_sign_changes": sign_changes,
        "largest_absolute_difference": largest,
        "largest_ratio_to_tolerance": tolerance_ratio,
    }
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(report, indent=2) + "\n")
    for name in sessions:
        print(
            f"{name}: future mask logits {over_tolerance[name]} of {future_values} values over the tolerance, "
            f"{sign_changes[name]} sign changes; largest differences "
            + ", ".join(f"{output} {value:.2e}" for output, value in largest[name].items())
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
