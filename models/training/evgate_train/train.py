"""Trains the suppression network on simulated sequences (docs/sequence-format.md).

    python -m evgate_train.train --data ../../data/suite-v5-full/train \
        --manifest ../../data/suite-v5-full/manifest.json --run-dir runs/S --size S --steps 20000

Stateful: each of --streams batch slots plays one sequence from its start to its end
(`streams.StreamSampler`), --windows-per-step windows per optimiser step, and the recurrent
state is carried from step to step, detached after each (truncated back-propagation through
time); it is zero only where a stream starts. Targets come from the 10 ms ground-truth grid at
--horizons horizons per window, always including the scored 100 ms. Writes
runs/<name>/checkpoint.pt (resumable with --resume: weights, optimiser, step, random states and
the data cursor), log.jsonl (one line of losses per step), val.jsonl (with --val-data) and
config.json.
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
from functools import partial
from pathlib import Path

import numpy as np
import torch
from torch.optim.swa_utils import AveragedModel, get_ema_multi_avg_fn
from tqdm import tqdm

from .checkpoint import (
    load_checkpoint,
    save_checkpoint,
    with_encoder_width,
    with_flow_upsampling,
    with_global_context,
    with_input_channels,
    with_input_normalisation,
    with_mask_decoder_width,
    with_spatial_gru_gates,
    with_time_conditioning,
)
from .evaluate import aggregate, evaluate_sequence
from .flow_upsampling import FLOW_UPSAMPLINGS
from .input_normalisation import INPUT_NORMALISATIONS
from .jitter import JitterRanges
from .network import FIRST_SPATIAL_GRU_STAGE, VOXEL_BINS, NetworkConfig, SuppressionNetwork, check_input_size
from .objective import LossWeights, window_objective
from .parallel_streams import ShardedStreams
from .sequence import load_sequence
from .streams import StreamSampler, StreamStep, preset_of
from .time_conditioning import VARIANTS
from .windows import SCORED_HORIZON_MS

# The weight average's checkpoint, beside checkpoint.pt in the run folder.
EMA_FILE = "ema.pt"

log = logging.getLogger("evgate_train.train")


class TrainingSetupError(ValueError):
    """A training run that cannot start: missing data, manifest or inconsistent resume."""


def manifest_digest(path: Path) -> str:
    """SHA-256 of the manifest's content without its measured wall times (`wall-s`, at any
    depth): the same split regenerated on another machine, bit for bit from its seeds, digests
    the same, so a campaign resumes there."""
    try:
        manifest = json.loads(path.read_text())
    except (OSError, ValueError) as error:
        raise TrainingSetupError(f"{path}: cannot read the training manifest: {error}") from error

    def without_wall_times(value):
        if isinstance(value, dict):
            return {key: without_wall_times(item) for key, item in value.items() if key != "wall-s"}
        if isinstance(value, list):
            return [without_wall_times(item) for item in value]
        return value

    canonical = json.dumps(without_wall_times(manifest), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(canonical.encode()).hexdigest()


def drop_records_after(path: Path, step: int) -> None:
    """Removes the records of steps past `step` from a JSON-lines log: a run that stopped between
    two checkpoints logged steps that the resumed run computes again. A run killed mid-write (or
    by a full disk) leaves a partial last line; it is dropped too."""
    if not path.exists():
        return
    lines = path.read_text().splitlines(keepends=True)
    kept = []
    for number, line in enumerate(lines, start=1):
        try:
            record = json.loads(line)
        except json.JSONDecodeError as error:
            if number == len(lines):
                break
            raise TrainingSetupError(f"{path}: line {number} is not a JSON record ({error})") from error
        if record["step"] <= step:
            kept.append(line)
    if len(kept) < len(lines):
        path.write_text("".join(kept))
        log.info("%s: dropped %d records past step %d", path, len(lines) - len(kept), step)


def learning_rate(step: int, total: int, peak: float, warmup: int, time_spent: float = 0.0) -> float:
    """Linear warm-up, then cosine decay to a tenth of the peak. The decay's progress is the
    larger of the steps done after warm-up and `time_spent` (the share of a time budget used), so
    a run that its budget ends still anneals."""
    if step < warmup:
        return peak * (step + 1) / warmup
    progress = min(1.0, max((step - warmup) / max(1, total - warmup), time_spent))
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


def parse_crop(text: str) -> tuple[int, int]:
    height, separator, width = text.partition("x")
    try:
        size = (int(height), int(width)) if separator else (int(text), int(text))
    except ValueError:
        raise TrainingSetupError(f"--crop {text!r}: expected HEIGHTxWIDTH, e.g. 272x352, or one side") from None
    check_input_size(*size)
    return size


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
    parser.add_argument(
        "--input-normalisation",
        choices=INPUT_NORMALISATIONS,
        help="how the network rescales its voxel input: global (as given, the default for a new network) "
        "or local (by the RMS of the active cells around each pixel); with --init-from it switches the "
        "checkpoint's network, keeping every weight; with --resume it must match the checkpoint",
    )
    parser.add_argument(
        "--voxel-bins",
        type=int,
        help="time bins of the voxel input (2, the runtime's, for a new network); with --init-from the "
        "checkpoint's first convolution is re-binned so that it starts computing what it computed",
    )
    parser.add_argument(
        "--motion-compensated-channel",
        action="store_true",
        help="add the ego-motion-compensated event image as an input channel (training and Python "
        "evaluation only; the runtime does not build it); with --init-from it starts at zero weight",
    )
    parser.add_argument(
        "--flow-upsampling",
        choices=FLOW_UPSAMPLINGS,
        help="how the coarse flow is upsampled: bilinear (the default for a new network) or convex "
        "(mask-guided, `flow_upsampling`); with --init-from a convex path is added with its gate closed, "
        "so the checkpoint's outputs are unchanged at first; with --resume it must match the checkpoint",
    )
    parser.add_argument(
        "--mask-decoder-width-factor",
        type=int,
        help="the mask decoder's width in multiples of the base width (1 for a new network); with "
        "--init-from the checkpoint's decoder is widened with its outputs unchanged at first; with "
        "--resume it must match the checkpoint",
    )
    parser.add_argument(
        "--first-spatial-gru-stage",
        type=int,
        help="encoder stages from this one on get depthwise-separable 3x3 ConvGRU gates, the others 1x1 "
        f"({FIRST_SPATIAL_GRU_STAGE} for a new network); with --init-from a 1x1 gate becomes a 3x3 one "
        "computing the same at first; with --resume it must match the checkpoint",
    )
    parser.add_argument(
        "--encoder-base-channels",
        type=int,
        help="the encoder's first-stage width, doubled at each stage (the size's base width for a new "
        "network); the decoders keep the base width; with --init-from the checkpoint's encoder is widened "
        "with its outputs unchanged at first; with --resume it must match the checkpoint",
    )
    parser.add_argument(
        "--global-context",
        action="store_true",
        help="the mask decoder reads the bottleneck scaled and shifted by an MLP of its mean over the frame "
        "(`global_context`); with --init-from the modulation starts at zero, so the checkpoint's outputs "
        "are unchanged at first; with --resume the checkpoint must have it too",
    )
    parser.add_argument("--steps", type=int, default=20000, help="optimiser steps (the learning-rate schedule's length)")
    parser.add_argument("--streams", type=int, default=4, help="sequences played side by side (the batch)")
    parser.add_argument(
        "--windows-per-step", type=int, default=4, help="consecutive 50 ms windows per step (the truncation length)"
    )
    parser.add_argument(
        "--crop",
        default="272x352",
        help="HEIGHTxWIDTH of each stream's fixed crop of the padded frame, multiples of 16 (default: a whole "
        "346x260 frame as evaluation pads it, so attention tokens and normalisation see what they see there)",
    )
    parser.add_argument(
        "--horizons", type=int, default=3, help="forecast horizons per window: 100 ms and others of the 10 ms grid"
    )
    parser.add_argument("--lr", type=float, default=1e-3, help="peak learning rate (AdamW)")
    parser.add_argument("--warmup", type=int, default=100, help="warm-up steps")
    parser.add_argument("--weight-decay", type=float, default=1e-4, help="AdamW weight decay")
    parser.add_argument("--dice-weight", type=float, default=1.0, help="Dice term weight (0 disables Dice)")
    parser.add_argument("--positive-weight", type=float, default=3.0, help="BCE weight of IMO pixels")
    parser.add_argument("--flow-weight", type=float, default=0.1, help="flow L1 weight (object and background means)")
    parser.add_argument(
        "--smoothness-weight", type=float, default=0.02, help="Charbonnier smoothness weight (not across object edges)"
    )
    parser.add_argument(
        "--fired-pixel-weight",
        type=float,
        default=0.0,
        help="extra mask BCE weight of the pixels with an event within 5 ms of the mask's time, those "
        "the gate judges by it (0 = uniform)",
    )
    parser.add_argument(
        "--small-object-area",
        type=float,
        default=0.0,
        help="IMO pixels of a true 8-connected component smaller than this many pixels weigh this area / "
        "its area times as much in the mask BCE, at most 8 times (0 = off): the frame-mean mIoU and "
        "R@0.5 count small objects as much as large ones",
    )
    parser.add_argument(
        "--focal-gamma",
        type=float,
        default=0.0,
        help="focal exponent of the current and future mask BCE: each pixel's term scaled by (1 - p_t)^gamma, "
        "p_t the probability of its true class (0 = plain BCE)",
    )
    parser.add_argument("--contrast-weight", type=float, default=0.0, help="contrast-maximisation weight (0 = off)")
    parser.add_argument(
        "--true-mask-warp-weight",
        type=float,
        default=0.0,
        help="weight of the true current mask warped by the predicted flow against the true future "
        "mask (0 disables)",
    )
    parser.add_argument("--max-contrast-events", type=int, default=4000, help="events per future window for CM")
    parser.add_argument(
        "--forecast-ramp-steps",
        type=int,
        default=0,
        help="curriculum: the forecast terms (future mask, flow, smoothness, contrast) ramp linearly from 0 to "
        "their weights over these steps, so the current mask is learnt first",
    )
    parser.add_argument("--no-augment", action="store_true", help="disable flips and polarity inversion")
    parser.add_argument(
        "--event-jitter",
        action="store_true",
        help="jitter each stream's input events (dropout, polarity flips, local rate scaling) within the "
        "--jitter-* ranges; targets are unchanged",
    )
    parser.add_argument(
        "--jitter-max-dropout", type=float, default=0.5, help="a stream drops a share of its events drawn from [0, this)"
    )
    parser.add_argument(
        "--jitter-max-polarity-flip",
        type=float,
        default=0.1,
        help="a stream flips the polarity of a share of its events drawn from [0, this]",
    )
    parser.add_argument(
        "--jitter-min-rate",
        type=float,
        default=0.25,
        help="lowest local keep factor of a stream's smooth rate field (drawn log-uniformly from [this, 1])",
    )
    parser.add_argument("--seed", type=int, default=7, help="seed of weights, sampling and augmentation")
    parser.add_argument(
        "--threads",
        type=int,
        default=1,
        help="torch CPU threads; on a shared 2-core machine 1 is several times faster than 2 "
        "(OpenMP workers spin on busy cores)",
    )
    parser.add_argument(
        "--data-workers",
        type=int,
        default=0,
        help="processes that build the training windows, each playing an equal share of --streams "
        "(`parallel_streams`; a GPU's large batch needs several); 0 = one thread beside training. "
        "A resumed run keeps its count",
    )
    parser.add_argument("--bf16", action="store_true", help="bfloat16 autocast of the forward pass (CPU AVX-512 BF16)")
    parser.add_argument(
        "--channels-last",
        action="store_true",
        help="keep the weights and the input in the channels-last memory layout: the same arithmetic, "
        "slower per step on a 2-core CPU (model card)",
    )
    parser.add_argument("--checkpoint-every", type=int, default=50, help="steps between checkpoints")
    parser.add_argument(
        "--val-data", type=Path, help="directory of validation .npz sequences, scored every --val-every steps"
    )
    parser.add_argument("--val-every", type=int, default=500, help="steps between validation scores")
    parser.add_argument(
        "--val-seconds", type=float, default=0.0, help="score only each validation sequence's leading seconds (0 = all)"
    )
    parser.add_argument(
        "--stop-at-step",
        type=int,
        default=0,
        help="end the run at this step while keeping the learning-rate schedule of --steps "
        "(a campaign spread over sessions, or short ablations that match a longer run); 0 = run all --steps",
    )
    parser.add_argument(
        "--device",
        default="cpu",
        help="torch device: cpu, or cuda (convolutions and matrix products in TF32 there)",
    )
    parser.add_argument(
        "--time-budget-s",
        type=float,
        default=0.0,
        help="end this process after so many seconds of training; the learning rate then decays by the larger "
        "of the share of --steps done and the share of this budget spent (`learning_rate`); 0 = none",
    )
    parser.add_argument(
        "--ema-decay",
        type=float,
        default=0.0,
        help="also keep an exponential moving average of the weights and batch-norm statistics, with this "
        "decay per step, in run-dir/ema.pt (a checkpoint every tool reads, saved with checkpoint.pt and "
        "resumed with it); val scores it too, under 'ema'. 0 = off; training itself is unchanged",
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


def random_states() -> dict:
    return {"python": random.getstate(), "numpy": np.random.get_state(), "torch": torch.get_rng_state()}


def restore_random_states(states: dict) -> None:
    random.setstate(states["python"])
    np.random.set_state(states["numpy"])
    torch.set_rng_state(states["torch"])


@torch.no_grad()
def replayed_states(network: SuppressionNetwork, sampler: StreamSampler, device: torch.device) -> list[torch.Tensor]:
    """The recurrent states of every stream at its cursor, rebuilt by playing its windows so far
    through the current weights (a checkpoint stays a few MB instead of holding them)."""
    states = network.initial_states(sampler.streams, sampler.crop_height, sampler.crop_width, device)
    was_training = network.training
    network.eval()
    horizon = torch.full((1, 1), float(SCORED_HORIZON_MS), device=device)
    for slot in range(sampler.streams):
        slot_states = [s[slot : slot + 1] for s in states]
        for voxel in sampler.played_voxels(slot):
            slot_states = network(torch.from_numpy(voxel)[None].to(device), horizon, slot_states).states
        for state, rebuilt in zip(states, slot_states):
            state[slot : slot + 1] = rebuilt
    network.train(was_training)
    return states


def carried_states(states: list[torch.Tensor], starts: np.ndarray) -> list[torch.Tensor]:
    """The recurrent states entering a step: zero for the streams that start there, the
    previous step's (detached: truncated back-propagation) for the others."""
    starting = torch.from_numpy(starts).to(states[0].device).view(-1, 1, 1, 1)
    return [torch.where(starting, torch.zeros_like(s), s.detach()) for s in states]


def train_step(
    network: SuppressionNetwork,
    optimiser: torch.optim.Optimizer,
    drawn: StreamStep,
    states: list[torch.Tensor],
    weights: LossWeights,
    bf16: bool = False,
    channels_last: bool = False,
) -> tuple[list[torch.Tensor], dict[str, torch.Tensor]]:
    """One optimiser step over a stream step's windows, the states carried through them; returns
    the states at its end and the window-averaged losses (with the gradient norm)."""
    states = carried_states(states, drawn.starts)
    device = states[0].device
    sums: dict[str, torch.Tensor] = {}
    for batch in drawn.windows:
        batch = batch.to(device)
        voxel = batch.voxel.contiguous(memory_format=torch.channels_last) if channels_last else batch.voxel
        with torch.autocast(device.type, dtype=torch.bfloat16, enabled=bf16):
            out = network(voxel, batch.horizons_ms, states)
        states = out.states
        for key, value in window_objective(out, batch, weights).items():
            sums[key] = sums.get(key, 0.0) + value.float() / len(drawn.windows)
    optimiser.zero_grad(set_to_none=True)
    sums["total"].backward()
    sums["grad_norm"] = torch.nn.utils.clip_grad_norm_(network.parameters(), 1.0)
    optimiser.step()
    return [s.detach() for s in states], sums


def weight_average(network: SuppressionNetwork, decay: float, path: Path, start_step: int) -> AveragedModel | None:
    """The exponential moving average of `network` (None for decay 0), continued from `path` when
    it holds the resumed step; otherwise it starts from the network's current weights."""
    if decay == 0:
        return None
    average = AveragedModel(network, multi_avg_fn=get_ema_multi_avg_fn(decay), use_buffers=True)
    if start_step > 0 and path.exists():
        saved = load_checkpoint(path)
        if saved.step == start_step:
            average.module.load_state_dict(saved.network.state_dict())
            average.n_averaged.fill_(1)  # average from here on; 0 would copy the next weights
            return average
        log.warning("%s holds step %d, not the resumed %d: the average starts again", path, saved.step, start_step)
    return average


def validation_scores(network: SuppressionNetwork, sequences: list, seconds: float) -> dict:
    """mIoU, pIoU and R@0.5 of the current mask and of the 100 ms forecast, means over the
    EVIMO-like presets and per preset (evaluation's aggregate)."""
    was_training = network.training
    per_sequence = [
        (
            sequence.preset,
            {
                key: score.summary()
                for key, score in evaluate_sequence(
                    network, sequence, [float(SCORED_HORIZON_MS)], with_baselines=False, max_seconds=seconds
                ).items()
            },
        )
        for sequence in sequences
    ]
    network.train(was_training)
    summary = aggregate(per_sequence)
    keep = ("miou", "piou", "r50")

    def rounded(value: float) -> float | None:
        return round(value, 4) if math.isfinite(value) else None

    return {
        "evimo-like": {
            key: {m: rounded(v) for m, v in metrics.items() if m in keep}
            for key, metrics in summary["evimo-like-mean"].items()
        },
        "presets": {
            preset: {key: {m: rounded(v) for m, v in metrics.items() if m in keep} for key, metrics in keys.items()}
            for preset, keys in summary["presets"].items()
        },
    }


def train(args: argparse.Namespace) -> Path:
    torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    if device.type == "cuda":
        if not torch.cuda.is_available():
            raise TrainingSetupError(f"--device {args.device}: torch sees no CUDA device")
        torch.backends.cudnn.benchmark = True
        torch.backends.cuda.matmul.allow_tf32 = True
        torch.backends.cudnn.allow_tf32 = True
    if not 0.0 <= args.ema_decay < 1.0:
        raise TrainingSetupError(f"--ema-decay {args.ema_decay}: must be 0 (off) or in (0, 1)")
    if args.time_budget_s < 0:
        raise TrainingSetupError(f"--time-budget-s {args.time_budget_s}: must be 0 (none) or more")
    if args.fired_pixel_weight < 0:
        raise TrainingSetupError(f"--fired-pixel-weight {args.fired_pixel_weight}: must be 0 (uniform) or more")
    if args.small_object_area < 0:
        raise TrainingSetupError(f"--small-object-area {args.small_object_area}: must be 0 (off) or more pixels")
    if args.focal_gamma < 0:
        raise TrainingSetupError(f"--focal-gamma {args.focal_gamma}: must be 0 (plain BCE) or more")
    if args.init_time_conditioning is not None and (args.init_from is None or args.resume):
        raise TrainingSetupError(
            f"--init-time-conditioning {args.init_time_conditioning}: needs --init-from and no --resume "
            "(it switches the variant of the network a new run starts from)"
        )
    crop_height, crop_width = parse_crop(args.crop)
    keep = {p for p in args.presets.split(",") if p}
    paths = [p for p in sorted(args.data.rglob("*.npz")) if not keep or preset_of(p) in keep]
    if not paths:
        raise TrainingSetupError(
            f"{args.data}: no .npz sequences found" + (f" of the presets {sorted(keep)}" if keep else "")
        )
    digest = manifest_digest(args.manifest)
    checkpoint_path = args.run_dir / "checkpoint.pt"
    train_config = {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items()}
    start_step, optimiser_state, continuation = 0, None, None
    if args.resume and checkpoint_path.exists():
        checkpoint = load_checkpoint(checkpoint_path)
        if checkpoint.manifest_sha256 != digest:
            raise TrainingSetupError(
                f"{checkpoint_path}: trained on manifest {checkpoint.manifest_sha256[:12]}, "
                f"but --manifest hashes to {digest[:12]}"
            )
        network, start_step, optimiser_state = checkpoint.network, checkpoint.step, checkpoint.optimiser_state
        resumed_normalisation = network.config.input_normalisation
        if args.input_normalisation not in (None, resumed_normalisation):
            raise TrainingSetupError(
                f"--input-normalisation {args.input_normalisation}: {checkpoint_path} was trained with "
                f"{resumed_normalisation}; a resumed run keeps its network"
            )
        resumed = network.config
        if (args.voxel_bins or resumed.voxel_bins, args.motion_compensated_channel or resumed.motion_compensated_channel) != (
            resumed.voxel_bins,
            resumed.motion_compensated_channel,
        ):
            raise TrainingSetupError(
                f"--voxel-bins {args.voxel_bins} / --motion-compensated-channel: {checkpoint_path} takes "
                f"{resumed.voxel_bins} bins and motion_compensated_channel={resumed.motion_compensated_channel}; "
                "a resumed run keeps its network"
            )
        if args.flow_upsampling not in (None, resumed.flow_upsampling):
            raise TrainingSetupError(
                f"--flow-upsampling {args.flow_upsampling}: {checkpoint_path} upsamples its flow "
                f"{resumed.flow_upsampling}; a resumed run keeps its network"
            )
        for flag, value, name in (
            ("--mask-decoder-width-factor", args.mask_decoder_width_factor, "mask_decoder_width_factor"),
            ("--first-spatial-gru-stage", args.first_spatial_gru_stage, "first_spatial_gru_stage"),
        ):
            if value not in (None, getattr(resumed, name)):
                raise TrainingSetupError(
                    f"{flag} {value}: {checkpoint_path} has {name.replace('_', ' ')} {getattr(resumed, name)}; "
                    "a resumed run keeps its network"
                )
        if args.encoder_base_channels not in (None, resumed.state_channels[0]):
            raise TrainingSetupError(
                f"--encoder-base-channels {args.encoder_base_channels}: {checkpoint_path} has an encoder "
                f"{resumed.state_channels[0]} channels wide at its first stage; a resumed run keeps its network"
            )
        if args.global_context and not resumed.global_context:
            raise TrainingSetupError(
                f"--global-context: {checkpoint_path} has no global context; a resumed run keeps its network"
            )
        continuation = checkpoint.continuation
        for records in ("log.jsonl", "val.jsonl"):
            drop_records_after(args.run_dir / records, start_step)
        log.info("resuming %s at step %d", checkpoint_path, start_step)
    elif args.init_from is not None:
        network = load_checkpoint(args.init_from).network
        if args.init_time_conditioning is not None:
            network = with_time_conditioning(network, args.init_time_conditioning)
        if args.input_normalisation is not None:
            network = with_input_normalisation(network, args.input_normalisation)
        if args.voxel_bins is not None or args.motion_compensated_channel:
            network = with_input_channels(
                network, args.voxel_bins or network.config.voxel_bins, args.motion_compensated_channel
            )
        if args.flow_upsampling is not None:
            network = with_flow_upsampling(network, args.flow_upsampling)
        if args.mask_decoder_width_factor is not None:
            network = with_mask_decoder_width(network, args.mask_decoder_width_factor)
        if args.first_spatial_gru_stage is not None:
            network = with_spatial_gru_gates(network, args.first_spatial_gru_stage)
        if args.encoder_base_channels is not None:
            network = with_encoder_width(network, args.encoder_base_channels)
        if args.global_context:
            network = with_global_context(network)
        config = network.config
        log.info(
            "initialised from %s (%s, %s, %s input normalisation)",
            args.init_from, config.size, config.time_conditioning, config.input_normalisation,
        )
    else:
        seed_everything(args.seed)
        network = SuppressionNetwork(
            NetworkConfig(
                size=args.size,
                time_conditioning=args.time_conditioning,
                input_normalisation=args.input_normalisation or "global",
                voxel_bins=args.voxel_bins or VOXEL_BINS,
                motion_compensated_channel=args.motion_compensated_channel,
                flow_upsampling=args.flow_upsampling or "bilinear",
                mask_decoder_width_factor=args.mask_decoder_width_factor or 1,
                first_spatial_gru_stage=(
                    FIRST_SPATIAL_GRU_STAGE if args.first_spatial_gru_stage is None else args.first_spatial_gru_stage
                ),
                encoder_base_channels=args.encoder_base_channels,
                global_context=args.global_context,
            )
        )
    if args.data_workers < 0:
        raise TrainingSetupError(f"--data-workers {args.data_workers}: must be 0 (in-process) or more")
    sampler = (StreamSampler if args.data_workers == 0 else partial(ShardedStreams, args.data_workers))(
        paths,
        args.streams,
        args.windows_per_step,
        crop_height,
        crop_width,
        args.horizons,
        args.max_contrast_events if args.contrast_weight > 0 else 0,
        not args.no_augment,
        args.seed,
        JitterRanges(args.jitter_max_dropout, args.jitter_max_polarity_flip, args.jitter_min_rate)
        if args.event_jitter
        else None,
        network.config,
    )
    if continuation is not None:
        sampler.load_state_dict(continuation["data"])
        restore_random_states(continuation["random"])
    else:
        seed_everything(args.seed + start_step)
    validation = sorted(args.val_data.rglob("*.npz")) if args.val_data is not None else []
    if args.val_data is not None and not validation:
        raise TrainingSetupError(f"--val-data {args.val_data}: no .npz sequences found")
    weights = LossWeights(
        dice=args.dice_weight,
        positive=args.positive_weight,
        flow=args.flow_weight,
        smoothness=args.smoothness_weight,
        contrast=args.contrast_weight,
        fired_pixels=args.fired_pixel_weight,
        small_object_area=args.small_object_area,
        true_mask_warp=args.true_mask_warp_weight,
        focal_gamma=args.focal_gamma,
    )
    network.to(device)
    if args.channels_last:
        network.to(memory_format=torch.channels_last)
    optimiser = torch.optim.AdamW(network.parameters(), lr=args.lr, weight_decay=args.weight_decay)
    if optimiser_state is not None:
        optimiser.load_state_dict(optimiser_state)
    args.run_dir.mkdir(parents=True, exist_ok=True)
    (args.run_dir / "config.json").write_text(
        json.dumps(
            {"train": train_config, "network": dataclasses.asdict(network.config), "loss": dataclasses.asdict(weights),
             "manifest_sha256": digest, "sequences": [str(p.relative_to(args.data)) for p in paths]},
            indent=2,
        )
    )
    average = weight_average(network, args.ema_decay, args.run_dir / EMA_FILE, start_step)
    network.train()
    states = replayed_states(network, sampler, device)
    validation_sequences = [load_sequence(p) for p in validation]

    def drawn_with_cursor() -> tuple[StreamStep, dict]:
        drawn = sampler.step()
        return drawn, sampler.state_dict()

    # The next step's windows are built on the other core while this step computes; each comes
    # with the data cursor just after it, which is what a checkpoint after that step stores.
    drawing = ThreadPoolExecutor(max_workers=1, thread_name_prefix="windows")
    upcoming = drawing.submit(drawn_with_cursor)
    cursor = sampler.state_dict()

    def save(path: Path, step: int) -> None:
        # The average first: a checkpoint.pt of step N means ema.pt holds step N too.
        if average is not None:
            save_checkpoint(args.run_dir / EMA_FILE, average.module, None, step, digest, train_config)
        save_checkpoint(
            path, network, optimiser, step, digest, train_config, {"data": cursor, "random": random_states()}
        )

    def validate(step: int) -> None:
        scores = validation_scores(network, validation_sequences, args.val_seconds)
        if average is not None:
            scores["ema"] = validation_scores(average.module, validation_sequences, args.val_seconds)
        with open(args.run_dir / "val.jsonl", "a") as val_file:
            val_file.write(json.dumps({"step": step, **scores}) + "\n")
        log.info("val at step %d: %s", step, json.dumps(scores["evimo-like"]))

    saved_step = start_step
    started = time.monotonic()
    last_step = min(args.steps, args.stop_at_step) if args.stop_at_step > 0 else args.steps
    with open(args.run_dir / "log.jsonl", "a") as log_file, tqdm(
        total=last_step, initial=start_step, desc=f"train {network.config.size}", unit="step"
    ) as progress:
        for step in range(start_step, last_step):
            if args.time_budget_s > 0 and time.monotonic() - started >= args.time_budget_s:
                last_step = step
                log.info("time budget of %.0f s spent at step %d", args.time_budget_s, step)
                break
            spent = (time.monotonic() - started) / args.time_budget_s if args.time_budget_s > 0 else 0.0
            rate = learning_rate(step, args.steps, args.lr, args.warmup, spent)
            for group in optimiser.param_groups:
                group["lr"] = rate
            drawn, cursor = upcoming.result()
            if step + 1 < last_step:
                upcoming = drawing.submit(drawn_with_cursor)
            states, sums = train_step(
                network, optimiser, drawn, states, forecast_ramped(weights, step, args.forecast_ramp_steps),
                args.bf16, args.channels_last,
            )
            if average is not None:
                average.update_parameters(network)
            record = {k: round(float(v.detach()), 5) for k, v in sums.items()}
            record.update(
                step=step + 1, lr=rate, stream_starts=int(drawn.starts.sum()),
                elapsed_s=round(time.monotonic() - started, 1),
            )
            log_file.write(json.dumps(record) + "\n")
            log_file.flush()
            progress.update(1)
            progress.set_postfix(
                loss=record["total"], mask=record["mask"], future=record["future_mask"], iou=record["mask_iou"]
            )
            if (step + 1) % args.checkpoint_every == 0 or step + 1 == last_step:
                save(checkpoint_path, step + 1)
                saved_step = step + 1
            if validation_sequences and ((step + 1) % args.val_every == 0 or step + 1 == last_step):
                validate(step + 1)
    drawing.shutdown(cancel_futures=True)
    if saved_step != last_step:
        save(checkpoint_path, last_step)
    log.info("stopped at step %d in %.0f s; checkpoint %s", last_step, time.monotonic() - started, checkpoint_path)
    return checkpoint_path


def main(argv: list[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    train(build_parser().parse_args(argv))
    return 0


if __name__ == "__main__":
    sys.exit(main())
