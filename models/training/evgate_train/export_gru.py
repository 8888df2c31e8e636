"""`ConvGRU.forward` written so that ONNX Runtime keeps the whole cell in its blocked (NCHWc)
layout: the same weights and function, without the concatenations, the channel split and the
subtraction that each force a reorder to plain NCHW and back.

ONNX Runtime's NCHWc transformer runs convolutions, Add, Mul, Sigmoid and Tanh on blocked
tensors, but not Concat of a graph input, Split, Slice or Sub, and a graph input (the state)
is never blocked unless a convolution reads it. The cell is therefore rewritten as:

- a convolution of the concatenation [x, h] is the sum of a convolution of x and one of h
  (split weights; a depthwise 3x3 of a concatenation is one per part); the Add then fuses
  into the convolution, and the gate's Sigmoid / Tanh into it as its activation;
- the reset and update gates are two convolutions instead of one split in two;
- h enters through a depthwise 1x1 convolution of weight 1 (exact), which makes it a blocked
  tensor that Mul and Add accept, and c - h is c plus a depthwise convolution of weight -1.

Measured on the S export: `git show dd99da7:models/MODEL_CARD.md`, "CPU latency".
"""

import torch
import torch.nn.functional as F
from torch import nn

from .convgru import ConvGRU


def _pointwise_and_depthwise(gate: nn.Module) -> tuple[nn.Conv2d, nn.Conv2d | None]:
    """A gate convolution's 1x1 convolution and, for spatial gates, its depthwise 3x3."""
    if isinstance(gate, nn.Conv2d):
        return gate, None
    depthwise, pointwise = gate
    return pointwise, depthwise


def _gate_inputs(gate: nn.Module, parts: list[torch.Tensor], widths: list[int]) -> list[torch.Tensor]:
    """What the gate's 1x1 convolution sees of each concatenated part (`widths` channels each):
    the part itself, or for spatial gates its depthwise 3x3 (a depthwise convolution of a
    concatenation is one per part)."""
    _, depthwise = _pointwise_and_depthwise(gate)
    if depthwise is None:
        return parts
    inputs, start = [], 0
    for part, channels in zip(parts, widths):
        inputs.append(F.conv2d(part, depthwise.weight[start : start + channels], padding=1, groups=channels))
        start += channels
    return inputs


def _pointwise_rows(gate: nn.Module, inputs: list[torch.Tensor], widths: list[int], rows: slice) -> torch.Tensor:
    """Output channels `rows` of the gate's 1x1 convolution of the concatenated `inputs`, as a
    sum of one convolution per input (the bias on the first)."""
    pointwise, _ = _pointwise_and_depthwise(gate)
    total, start = None, 0
    for index, (part, channels) in enumerate(zip(inputs, widths)):
        columns = slice(start, start + channels)
        start += channels
        bias = pointwise.bias[rows] if index == 0 and pointwise.bias is not None else None
        term = F.conv2d(part, pointwise.weight[rows, columns], bias)
        total = term if total is None else total + term
    return total


def _scaled_identity(h: torch.Tensor, channels: int, factor: float) -> torch.Tensor:
    weight = torch.full((channels, 1, 1, 1), factor, dtype=h.dtype)
    return F.conv2d(h, weight, groups=channels)


def gru_step(cell: ConvGRU, x: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
    """`cell(x, h)`, arranged for ONNX Runtime's blocked layout (module docstring)."""
    # Channel counts from the weights: the traced export must see them as constants.
    hidden, stacked = (int(size) for size in _pointwise_and_depthwise(cell.candidate)[0].weight.shape[:2])
    widths = [stacked - hidden, hidden]
    blocked_h = _scaled_identity(h, hidden, 1.0)
    gate_inputs = _gate_inputs(cell.gates, [x, blocked_h], widths)
    reset = torch.sigmoid(_pointwise_rows(cell.gates, gate_inputs, widths, slice(0, hidden)))
    update = torch.sigmoid(_pointwise_rows(cell.gates, gate_inputs, widths, slice(hidden, 2 * hidden)))
    candidate_inputs = _gate_inputs(cell.candidate, [x, reset * blocked_h], widths)
    candidate = torch.tanh(_pointwise_rows(cell.candidate, candidate_inputs, widths, slice(0, hidden)))
    return blocked_h + update * (candidate + _scaled_identity(blocked_h, hidden, -1.0))
