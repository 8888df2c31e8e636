"""Training checkpoints: weights, optimiser, step, configuration, data manifest hash and the
run's continuation (data cursor, random states, the recurrent states being carried)."""

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from .network import NetworkConfig, SuppressionNetwork

TIME_CONDITIONING_PREFIX = "time_conditioning."
FIRST_CONVOLUTION_WEIGHT = "downsamples.0.0.weight"


class CheckpointError(ValueError):
    """A checkpoint file that cannot be read or lacks a field."""


@dataclass
class Checkpoint:
    network: SuppressionNetwork
    step: int
    manifest_sha256: str
    optimiser_state: dict | None
    train_config: dict
    # What a resumed run needs to continue the same stream: `train.continuation`.
    continuation: dict | None


def save_checkpoint(
    path: Path,
    network: SuppressionNetwork,
    optimiser,
    step: int,
    manifest_sha256: str,
    train_config: dict,
    continuation: dict | None = None,
) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_suffix(".tmp")
    torch.save(
        {
            "network_config": dataclasses.asdict(network.config),
            "weights": network.state_dict(),
            "optimiser": optimiser.state_dict() if optimiser is not None else None,
            "step": step,
            "manifest_sha256": manifest_sha256,
            "train_config": train_config,
            "continuation": continuation,
        },
        temporary,
    )
    # Rename last so an interrupted save never leaves a truncated checkpoint behind.
    temporary.replace(path)


def load_checkpoint(path: Path) -> Checkpoint:
    try:
        payload = torch.load(path, map_location="cpu", weights_only=False)
    except (OSError, RuntimeError) as error:
        raise CheckpointError(f"{path}: cannot read checkpoint: {error}") from error
    for field in ("network_config", "weights", "step", "manifest_sha256"):
        if field not in payload:
            raise CheckpointError(f"{path}: checkpoint lacks field {field!r}")
    network = SuppressionNetwork(NetworkConfig(**payload["network_config"]))
    network.load_state_dict(payload["weights"])
    return Checkpoint(
        network=network,
        step=int(payload["step"]),
        manifest_sha256=payload["manifest_sha256"],
        optimiser_state=payload.get("optimiser"),
        train_config=payload.get("train_config", {}),
        continuation=payload.get("continuation"),
    )


def with_input_normalisation(network: SuppressionNetwork, normalisation: str) -> SuppressionNetwork:
    """The same network (every weight) rescaling its input as `normalisation` says: the
    normalisations have no weights, so a trained network can be fine-tuned under another."""
    switched = SuppressionNetwork(dataclasses.replace(network.config, input_normalisation=normalisation))
    switched.load_state_dict(network.state_dict())
    return switched


def with_input_channels(network: SuppressionNetwork, voxel_bins: int, motion_compensated: bool) -> SuppressionNetwork:
    """The same network taking `voxel_bins` time bins and, if `motion_compensated`, the
    compensated event image, with every other weight kept. The first convolution starts out
    computing nearly what it computed before: a new bin's weights interpolate the old bins' at
    the new bin's centre (from 2 bins, each old bin's linear time weight is a sum of the new
    bins' weights, so the response to the raw grid is unchanged; only the standardisation's
    statistics differ), and a new compensated channel starts at zero weight."""
    config = dataclasses.replace(
        network.config, voxel_bins=voxel_bins, motion_compensated_channel=motion_compensated
    )
    widened = SuppressionNetwork(config)
    weights = network.state_dict()
    old = weights[FIRST_CONVOLUTION_WEIGHT]
    old_bins = network.config.voxel_bins
    old_centres = np.linspace(0.0, 1.0, old_bins)
    new = torch.zeros(old.shape[0], config.input_channels, *old.shape[2:], dtype=old.dtype)
    for bin_index, centre in enumerate(np.linspace(0.0, 1.0, voxel_bins)):
        lower = min(int(np.searchsorted(old_centres, centre, side="right")) - 1, old_bins - 2)
        share = (centre - old_centres[lower]) / (old_centres[lower + 1] - old_centres[lower])
        new[:, bin_index] = (1.0 - share) * old[:, lower] + share * old[:, lower + 1]
    if network.config.motion_compensated_channel and motion_compensated:
        new[:, -1] = old[:, -1]
    weights[FIRST_CONVOLUTION_WEIGHT] = new
    widened.load_state_dict(weights)
    return widened


def with_flow_upsampling(network: SuppressionNetwork, flow_upsampling: str) -> SuppressionNetwork:
    """The same network (every weight it has) upsampling its flow as `flow_upsampling` says. The
    convex upsampling's heads start at zero, where it adds nothing to the bilinear flow, so the
    outputs stay the same until training opens its gate; leaving it drops those heads."""
    switched = SuppressionNetwork(dataclasses.replace(network.config, flow_upsampling=flow_upsampling))
    target = switched.state_dict()
    switched.load_state_dict({name: w for name, w in network.state_dict().items() if name in target}, strict=False)
    return switched


def with_time_conditioning(network: SuppressionNetwork, variant: str) -> SuppressionNetwork:
    """A network of another time-conditioning variant holding every weight of `network` that the
    variant shares: the rows of an ablation that start from one trained network. Weights the
    variant adds are freshly initialised; only time-conditioning weights may differ."""
    config = dataclasses.replace(network.config, time_conditioning=variant)
    variant_network = SuppressionNetwork(config)
    source = network.state_dict()
    target = variant_network.state_dict()
    shared = {name: weight for name, weight in source.items() if name in target and target[name].shape == weight.shape}
    differing = (set(source) | set(target)) - set(shared)
    outside = sorted(name for name in differing if not name.startswith(TIME_CONDITIONING_PREFIX))
    if outside:
        raise CheckpointError(f"time-conditioning variant {variant!r} differs outside time conditioning: {outside[:3]}")
    variant_network.load_state_dict(shared, strict=False)
    return variant_network


def with_spatial_gru_gates(network: SuppressionNetwork, first_stage: int) -> SuppressionNetwork:
    """The same network with depthwise-separable 3x3 ConvGRU gates from encoder stage
    `first_stage` on. A 1x1 gate becomes a depthwise 3x3 whose centre tap is 1, followed by the
    old 1x1, so the network computes what it computed until training moves the other taps."""
    current = network.config.first_spatial_gru_stage
    if first_stage > current:
        raise CheckpointError(
            f"first spatial ConvGRU stage {first_stage}: the network already has 3x3 gates from stage "
            f"{current}, and turning a 3x3 gate into a 1x1 one would change what it computes"
        )
    switched = SuppressionNetwork(dataclasses.replace(network.config, first_spatial_gru_stage=first_stage))
    weights = network.state_dict()
    for stage in range(first_stage, current):
        for gate in ("gates", "candidate"):
            prefix = f"recurrent.{stage}.{gate}."
            pointwise_weight = weights.pop(prefix + "weight")
            weights[prefix + "1.weight"] = pointwise_weight
            weights[prefix + "1.bias"] = weights.pop(prefix + "bias")
            identity = torch.zeros(pointwise_weight.shape[1], 1, 3, 3, dtype=pointwise_weight.dtype)
            identity[:, 0, 1, 1] = 1.0
            weights[prefix + "0.weight"] = identity
    switched.load_state_dict(weights)
    return switched


def with_global_context(network: SuppressionNetwork) -> SuppressionNetwork:
    """The same network (every weight) with the mask decoder's global context added
    (`global_context`): its modulation starts at zero, so the outputs are unchanged at first."""
    if network.config.global_context:
        return network
    switched = SuppressionNetwork(dataclasses.replace(network.config, global_context=True))
    weights = switched.state_dict()
    weights.update(network.state_dict())
    switched.load_state_dict(weights)
    return switched


MASK_DECODER_PREFIX = "mask_decoder."
# Weights that read the mask decoder's features (its heads, the convex upsampling's): their new
# input channels start at zero weight.
MASK_FEATURE_READERS = (
    MASK_DECODER_PREFIX + "coarse_head.weight",
    MASK_DECODER_PREFIX + "heads.",
    "convex_upsampling.weight_logits.weight",
    "convex_upsampling.gate.weight",
)


def with_mask_decoder_width(network: SuppressionNetwork, factor: int) -> SuppressionNetwork:
    """The same network with a mask decoder `factor` times the base width. The old channels
    keep their weights and read none of the new ones (zero weights), and every head reads the
    new ones with zero weight, so the outputs are unchanged at first; the new channels' own
    weights are freshly initialised, so that training can use them at once."""
    current = network.config.mask_decoder_width_factor
    if factor < current:
        raise CheckpointError(
            f"mask decoder width factor {factor}: the network's is already {current}, and narrowing "
            "would drop trained channels"
        )
    widened = SuppressionNetwork(dataclasses.replace(network.config, mask_decoder_width_factor=factor))
    old_width = network.config.mask_decoder_width
    new_width = widened.config.mask_decoder_width
    weights = widened.state_dict()
    for name, old in network.state_dict().items():
        new = weights[name]
        if new.shape == old.shape:
            weights[name] = old
        elif name.startswith(MASK_FEATURE_READERS):
            # One row per output, one column per decoder channel.
            new.zero_()
            new[:, :old_width] = old
        elif name.startswith(MASK_DECODER_PREFIX + "convs.") and old.dim() == 4:
            # A level's 3x3 convolution reads [features, prediction]: the prediction's columns
            # follow the (now wider) features.
            new[:old_width] = 0.0
            new[:old_width, :old_width] = old[:, :old_width]
            new[:old_width, new_width:] = old[:, old_width:]
        else:
            # Rows of the reduction, the skip projections, the levels' biases and batch norms:
            # the old channels' values, the new channels' fresh ones.
            new[:old_width] = old
    widened.load_state_dict(weights)
    return widened


RECURRENT_PREFIX = "recurrent."


def _stacked_chunks(name: str, dim: int) -> int:
    """How many stage-wide blocks dimension `dim` of encoder weight `name` is made of: a
    ConvGRU reads [input, hidden] (two blocks), its gate convolution writes [reset, update]
    (two blocks) and its depthwise taps run over the stacked input; everything else holds one."""
    if not name.startswith(RECURRENT_PREFIX):
        return 1
    if dim == 1:
        return 2
    depthwise = name.endswith(".0.weight")
    return 2 if ".gates" in name or depthwise else 1


def _old_indices(new_size: int, chunks: int, old_size: int) -> torch.Tensor:
    """Where the old channels of a dimension sit in the widened one: the first channels of
    each of its `chunks` blocks (all of them where the dimension did not grow)."""
    new_block, old_block = new_size // chunks, old_size // chunks
    return torch.cat([torch.arange(old_block) + chunk * new_block for chunk in range(chunks)])


def with_encoder_width(network: SuppressionNetwork, encoder_base_channels: int) -> SuppressionNetwork:
    """The same network with an encoder `encoder_base_channels` wide at its first stage (each
    stage doubles it). The old channels keep their weights and read the new ones with zero
    weight, as do the decoders and the flow features, so every output and the old state
    channels are unchanged at first; the new channels' own weights are freshly initialised, so
    that they carry features and their readers receive gradient at once."""
    current = network.config.state_channels[0]
    if encoder_base_channels < current:
        raise CheckpointError(
            f"encoder base channels {encoder_base_channels}: the network's encoder is already {current} "
            "wide, and narrowing would drop trained channels"
        )
    widened = SuppressionNetwork(dataclasses.replace(network.config, encoder_base_channels=encoder_base_channels))
    weights = widened.state_dict()
    for name, old in network.state_dict().items():
        new = weights[name]
        if new.shape == old.shape:
            weights[name] = old
            continue
        rows = _old_indices(new.shape[0], _stacked_chunks(name, 0), old.shape[0])
        if old.dim() < 2 or new.shape[1] == old.shape[1]:
            new[rows] = old
            continue
        columns = _old_indices(new.shape[1], _stacked_chunks(name, 1), old.shape[1])
        new[rows] = 0.0
        new[rows[:, None], columns] = old
    widened.load_state_dict(weights)
    return widened
