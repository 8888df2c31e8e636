"""Trains the suppression network on simulated sequences (docs/sequence-format.md).

    python -m evgate_train.train --data ../../data/suite/train --manifest ../../data/suite/manifest.json \
        --run-dir runs/S --size S --steps 1500

Chunks of consecutive 50 ms windows carry the recurrent state; horizons come from the
sequences' uniformly sampled ones in [0, 100] ms. Writes runs/<name>/checkpoint.pt (resumable
with --resume), log.jsonl (one line of losses per step) and config.json.
"""

import argparse
import dataclasses
import hashlib
import json
import logging
import math
import random
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from .batches import ChunkSampler
from .checkpoint import load_checkpoint, save_checkpoint, with_time_conditioning
from .loader import chunk_batches
from .network import NetworkConfig, SuppressionNetwork, check_input_size
from .objective import LossWeights, window_objective
from .sequence import load_sequence
from .time_conditioning import VARIANTS

log = logging.getLogger("evgate_train.train")


class TrainingSetupError(ValueError):
    """A training run that cannot start: missing data, manifest or inconsistent resume."""


def manifest_digest(path: Path) -> str:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError as error:
        raise TrainingSetupError(f"{path}: cannot read the training manifest: {error}") from error


def learning_rate(step: int, total: int, peak: float, warmup: int, elapsed_share: float = 0.0) -> float:
    """Linear warm-up, then cosine decay to a tenth of the peak; under a time budget the decay
    follows whichever is further along, the steps or the budget's `elapsed_share`."""
    if step < warmup:
        return peak * (step + 1) / warmup
    progress = min(1.0, max((step - warmup) / max(1, total - warmup), elapsed_share))
    return peak * (0.1 + 0.9 * 0.5 * (1.0 + math.cos(math.pi * progress)))


def forecast_ramped(weights: LossWeights, step: int, ramp_steps: int) -> LossWeights:
    scale = min(1.0, step / ramp_steps) if ramp_steps > 0 else 1.0
    return dataclasses.replace(
        weights,
        future_mask=weights.future_mask * scale,
        flow=weights.flow * scale,
        smoothness=weights.smoothness * scale,
        contrast=weights.contrast * scale,
        true_mask_warp=weights.true_mask_warp * scale,
    )


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, required=True, help="directory searched recursively for training .npz sequences")
    parser.add_argument("--manifest", type=Path, required=True, help="the suite's manifest, hashed into the model")
    parser.add_argument("--run-dir", type=Path, required=True, help="checkpoint, logs and config go here")
    parser.add_argument("--presets", default="", help="comma-separated presets to train on (default: all)")
    parser.add_argument("--size", default="S", help="model size: XS, S, M or L")
    parser.add_argument(
        "--time-conditioning", default="position-aware", help="ATC variant: position-aware, reference or none"
    )
    parser.add_argument("--steps", type=int, default=1500, help="optimiser steps")
    parser.add_argument("--batch", type=int, default=4, help="chunks per step")
    parser.add_argument("--chunk-windows", type=int, default=4, help="consecutive 50 ms windows per chunk")
    parser.add_argument("--crop", type=int, default=112, help="square crop side in pixels (multiple of 16)")
    parser.add_argument("--lr", type=float, default=2e-3, help="peak learning rate (AdamW)")
    parser.add_argument("--warmup", type=int, default=50, help="warm-up steps")
    parser.add_argument("--weight-decay", type=float, default=1e-4, help="AdamW weight decay")
    parser.add_argument("--dice-weight", type=float, default=0.5, help="Dice term weight (0 disables Dice)")
    parser.add_argument("--positive-weight", type=float, default=1.0, help="BCE weight of IMO pixels")
    parser.add_argument("--flow-weight", type=float, default=0.1, help="flow L1 weight")
    parser.add_argument("--smoothness-weight", type=float, default=0.05, help="Charbonnier smoothness weight")
    parser.add_argument("--contrast-weight", type=float, default=1.0, help="contrast-maximisation weight")
    parser.add_argument(
        "--true-mask-warp-weight",
        type=float,
        default=0.0,
        help="weight of the true current mask warped by the predicted flow against the true future "
        "mask (0 disables)",
    )
    parser.add_argument("--max-contrast-events", type=int, default=4000, help="events per future window for CM")
    parser.add_argument(
        "--contrast-last-window-only",
        action="store_true",
        help="compute contrast maximisation on each chunk's last window only (about 1.1x faster steps on CPU "
        "since the term is batched)",
    )
    parser.add_argument(
        "--forecast-ramp-steps",
        type=int,
        default=0,
        help="curriculum from horizon 0: the forecast terms (future mask, flow, smoothness, contrast) "
        "ramp linearly from 0 to their weights over these steps, so the current mask is learnt first",
    )
    parser.add_argument("--no-augment", action="store_true", help="disable flips and polarity inversion")
    parser.add_argument(
        "--flow-target",
        default="forward",
        choices=("forward", "arrival"),
        help="flow L1 target: the simulator's forward flow (defined where a pixel leaves), or "
        "'arrival': inside each object's future footprint its mean flow, which backward warping needs",
    )
    parser.add_argument("--seed", type=int, default=7, help="seed of weights, sampling and augmentation")
    parser.add_argument(
        "--threads",
        type=int,
        default=1,
        help="torch CPU threads; on a shared 2-core machine 1 is several times faster than 2 "
        "(OpenMP workers spin on busy cores)",
    )
    parser.add_argument("--checkpoint-every", type=int, default=50, help="steps between checkpoints")
    parser.add_argument(
        "--keep-checkpoints-at",
        default="",
        help="comma-separated steps whose checkpoints are also kept as checkpoint-step<N>.pt "
        "(equal-step ablations against a longer run with the same schedule)",
    )
    parser.add_argument(
        "--stop-at-step",
        type=int,
        default=0,
        help="end the run at this step while keeping the learning-rate schedule of --steps "
        "(short ablations that match a longer run step for step); 0 = run all --steps",
    )
    parser.add_argument(
        "--device",
        default="cpu",
        help="torch device: cpu, or cuda (convolutions and matrix products in TF32 there)",
    )
    parser.add_argument(
        "--loader-workers",
        type=int,
        default=0,
        help="processes drawing training chunks ahead of the steps (0 = draw in the training process)",
    )
    parser.add_argument(
        "--time-budget-s",
        type=float,
        default=0.0,
        help="end the run after this many seconds of training, with the learning-rate decay paced by the "
        "elapsed share of the budget (a fixed lease on a GPU machine); 0 = no budget",
    )
    parser.add_argument("--resume", action="store_true", help="continue from run-dir/checkpoint.pt")
    parser.add_argument(
        "--init-from",
        type=Path,
        help="start from this checkpoint's weights (fine-tuning on other data): a fresh optimiser and "
        "schedule, step 0, this run's manifest; the network configuration comes from the checkpoint",
    )
    parser.add_argument(
        "--init-time-conditioning",
        choices=VARIANTS,
        help="with --init-from: switch the network to this time-conditioning variant, keeping every "
        "weight it shares with the checkpoint (ablation rows fine-tuned from one trained network)",
    )
    return parser


def train(args: argparse.Namespace) -> Path:
    torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    if device.type == "cuda":
        if not torch.cuda.is_available():
            raise TrainingSetupError(f"--device {args.device}: torch sees no CUDA device")
        torch.backends.cudnn.benchmark = True
        torch.backends.cuda.matmul.allow_tf32 = True
        torch.backends.cudnn.allow_tf32 = True
    if args.loader_workers < 0:
        raise TrainingSetupError(f"--loader-workers {args.loader_workers}: must be 0 or more")
    if args.time_budget_s < 0:
        raise TrainingSetupError(f"--time-budget-s {args.time_budget_s}: must be 0 (none) or more")
    if args.init_time_conditioning is not None and (args.init_from is None or args.resume):
        raise TrainingSetupError(
            f"--init-time-conditioning {args.init_time_conditioning}: needs --init-from and no --resume "
            "(it switches the variant of the network a new run starts from)"
        )
    check_input_size(args.crop, args.crop)
    paths = sorted(args.data.rglob("*.npz"))
    if not paths:
        raise TrainingSetupError(f"{args.data}: no .npz sequences found")
    digest = manifest_digest(args.manifest)
    checkpoint_path = args.run_dir / "checkpoint.pt"
    train_config = {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items()}
    start_step, optimiser_state = 0, None
    if args.resume and checkpoint_path.exists():
        checkpoint = load_checkpoint(checkpoint_path)
        if checkpoint.manifest_sha256 != digest:
            raise TrainingSetupError(
                f"{checkpoint_path}: trained on manifest {checkpoint.manifest_sha256[:12]}, "
                f"but --manifest hashes to {digest[:12]}"
            )
        network, start_step, optimiser_state = checkpoint.network, checkpoint.step, checkpoint.optimiser_state
        log.info("resuming %s at step %d", checkpoint_path, start_step)
    elif args.init_from is not None:
        network = load_checkpoint(args.init_from).network
        if args.init_time_conditioning is not None:
            network = with_time_conditioning(network, args.init_time_conditioning)
        log.info("initialised from %s (%s, %s)", args.init_from, network.config.size, network.config.time_conditioning)
    else:
        seed_everything(args.seed)
        network = SuppressionNetwork(NetworkConfig(size=args.size, time_conditioning=args.time_conditioning))
    log.info("loading %d sequences from %s", len(paths), args.data)
    # Decompression releases the GIL: threads load a suite of dozens of sequences several times faster.
    with ThreadPoolExecutor(max_workers=min(8, len(paths))) as pool:
        sequences = list(tqdm(pool.map(load_sequence, paths), total=len(paths), desc="loading", unit="seq"))
    keep = {p for p in args.presets.split(",") if p}
    if keep:
        sequences = [s for s in sequences if s.preset in keep]
        if not sequences:
            raise TrainingSetupError(f"{args.data}: no sequence of the presets {sorted(keep)}")
    # Resumed runs reseed by step so the data stream continues instead of repeating.
    seed_everything(args.seed + start_step)
    sampler = ChunkSampler(
        sequences,
        args.chunk_windows,
        args.crop,
        args.max_contrast_events,
        not args.no_augment,
        args.seed + start_step,
        flow_at_arrival=args.flow_target == "arrival",
    )
    weights = LossWeights(
        dice=args.dice_weight,
        positive=args.positive_weight,
        flow=args.flow_weight,
        smoothness=args.smoothness_weight,
        contrast=args.contrast_weight,
        true_mask_warp=args.true_mask_warp_weight,
    )
    network.to(device)
    optimiser = torch.optim.AdamW(network.parameters(), lr=args.lr, weight_decay=args.weight_decay)
    if optimiser_state is not None:
        optimiser.load_state_dict(optimiser_state)
    args.run_dir.mkdir(parents=True, exist_ok=True)
    (args.run_dir / "config.json").write_text(
        json.dumps(
            {"train": train_config, "network": dataclasses.asdict(network.config), "loss": dataclasses.asdict(weights),
             "manifest_sha256": digest, "sequences": [p.name for p in paths]},
            indent=2,
        )
    )
    keep_steps = {int(v) for v in args.keep_checkpoints_at.split(",") if v}
    network.train()
    drawn = chunk_batches(sampler, args.batch, args.loader_workers, args.seed + start_step)
    saved_step = start_step
    started = time.monotonic()
    with open(args.run_dir / "log.jsonl", "a") as log_file, tqdm(
        total=args.steps, initial=start_step, desc=f"train {network.config.size}", unit="step"
    ) as progress:
        last_step = min(args.steps, args.stop_at_step) if args.stop_at_step > 0 else args.steps
        for step in range(start_step, last_step):
            elapsed = time.monotonic() - started
            if args.time_budget_s > 0 and elapsed >= args.time_budget_s:
                last_step = step
                log.info("time budget of %.0f s spent at step %d", args.time_budget_s, step)
                break
            elapsed_share = elapsed / args.time_budget_s if args.time_budget_s > 0 else 0.0
            rate = learning_rate(step, args.steps, args.lr, args.warmup, elapsed_share)
            for group in optimiser.param_groups:
                group["lr"] = rate
            batches = [batch.to(device) for batch in next(drawn)]
            crop = args.crop
            states = network.initial_states(args.batch, crop, crop, device)
            sums: dict[str, torch.Tensor] = {}
            step_weights = forecast_ramped(weights, step, args.forecast_ramp_steps)
            for index, batch in enumerate(batches):
                out = network(batch.voxel, batch.horizons_ms, states)
                states = out.states
                with_contrast = not args.contrast_last_window_only or index == len(batches) - 1
                for key, value in window_objective(out, batch, step_weights, with_contrast).items():
                    sums[key] = sums.get(key, 0.0) + value / len(batches)
            optimiser.zero_grad(set_to_none=True)
            sums["total"].backward()
            gradient_norm = torch.nn.utils.clip_grad_norm_(network.parameters(), 1.0)
            optimiser.step()
            record = {k: round(float(v.detach()), 5) for k, v in sums.items()}
            record.update(
                step=step + 1, lr=rate, grad_norm=round(float(gradient_norm), 4),
                elapsed_s=round(time.monotonic() - started, 1),
            )
            log_file.write(json.dumps(record) + "\n")
            log_file.flush()
            progress.update(1)
            progress.set_postfix(
                loss=record["total"], mask=record["mask"], future=record["future_mask"], iou=record["mask_iou"]
            )
            if (step + 1) % args.checkpoint_every == 0 or step + 1 in (last_step, *keep_steps):
                save_checkpoint(checkpoint_path, network, optimiser, step + 1, digest, train_config)
                saved_step = step + 1
            if step + 1 in keep_steps:
                save_checkpoint(
                    args.run_dir / f"checkpoint-step{step + 1}.pt", network, optimiser, step + 1, digest, train_config
                )
    if saved_step != last_step:
        save_checkpoint(checkpoint_path, network, optimiser, last_step, digest, train_config)
    log.info("finished at step %d in %.0f s; checkpoint %s", last_step, time.monotonic() - started, checkpoint_path)
    return checkpoint_path


def main(argv: list[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    train(build_parser().parse_args(argv))
    return 0


if __name__ == "__main__":
    sys.exit(main())
