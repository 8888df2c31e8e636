"""Training checkpoints: weights, optimiser, step, configuration, data manifest hash and the
run's continuation (data cursor, random states, the recurrent states being carried)."""

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import torch

from .network import NetworkConfig, SuppressionNetwork

TIME_CONDITIONING_PREFIX = "time_conditioning."


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
