"""Time conditioning for K horizons at once, with its horizon-independent work done once.

`TimeConditioning` runs on K copies of the same features, one per horizon: the token norm,
the pooled keys and values, and K query-key products and softmaxes over h*w x h'*w' scores.
Only the horizon encoding differs between the copies, and it enters the query linearly:

    scores_k = (Q0 + q_k) K^T / sqrt(d) = S + b_k,   S shared, b_k one row per head

so softmax(S + b_k) V = (E (w_k * V)) / (E w_k) with E = exp(S - max S) and w_k = exp(b_k - max b_k):
one matrix product per head for all horizons, against K products and K softmaxes of the full
score matrix (measured: `git show dd99da7:models/MODEL_CARD.md`, "CPU latency"). The weights are the module's
own; only the order of the arithmetic changes.

E and w_k are at most 1 with a 1 in every row, so the denominator cannot overflow; it
underflows only if scores within one row spread by more than about 80 (float32's exponent),
far beyond what the trained model produces (checked by the export's parity test).
"""

import math

import torch
import torch.nn.functional as F

from .time_conditioning import TimeConditioning, horizon_encoding


def condition_horizons(module: TimeConditioning, features: torch.Tensor, horizons_ms: torch.Tensor) -> torch.Tensor:
    """`module(features expanded to K copies, horizons_ms)` for features [1, C, h, w] and
    horizons [K]: returns [K, C, h, w]."""
    horizons = horizons_ms.shape[0]
    _, channels, height, width = features.shape
    if module.variant == "none":
        return features.expand(horizons, -1, -1, -1)
    tokens = features.flatten(2).transpose(1, 2)  # [1, N, C]
    pooled = F.avg_pool2d(features, 3, stride=2, padding=1, count_include_pad=False)
    pooled_normalised = module.token_norm(pooled.flatten(2).transpose(1, 2))  # [1, M, C]
    time = module.time_embedding(horizon_encoding(horizons_ms, channels))  # [K, C]
    heads = module.heads
    head_channels = channels // heads
    scale = 1.0 / math.sqrt(head_channels)

    # Per head: keys [H, M, d] and values [H, M, d].
    key = module.key(pooled_normalised)[0].reshape(-1, heads, head_channels).transpose(0, 1)
    value = module.value(pooled_normalised)[0].reshape(-1, heads, head_channels).transpose(0, 1)
    # The query's horizon part q_k = time_k Wq^T + bq, and its score row b_k per head: [H, K, M].
    horizon_query = F.linear(time, module.query.weight, module.query.bias).reshape(horizons, heads, head_channels)
    horizon_scores = (horizon_query.transpose(0, 1) @ key.transpose(1, 2)) * scale
    horizon_weights = torch.exp(horizon_scores - horizon_scores.amax(dim=-1, keepdim=True))
    if module.variant == "position-aware":
        token_query = (module.token_norm(tokens)[0] @ module.query.weight.t()).reshape(-1, heads, head_channels)
        shared_scores = (token_query.transpose(0, 1) @ key.transpose(1, 2)) * scale  # [H, N, M]
        shared_weights = torch.exp(shared_scores - shared_scores.amax(dim=-1, keepdim=True))
    else:
        # The reference variant's query is the horizon part alone: S = 0 at every position.
        shared_weights = torch.ones(heads, height * width, key.shape[1], dtype=features.dtype)
    # [H, M, K, d + 1]: each horizon's weighted values, and its weights (for the denominator).
    value_and_one = torch.cat([value, torch.ones_like(value[..., :1])], dim=-1)
    weighted = horizon_weights.transpose(1, 2).unsqueeze(-1) * value_and_one.unsqueeze(2)
    summed = (shared_weights @ weighted.flatten(2)).reshape(heads, -1, horizons, head_channels + 1)
    attended = summed[..., :head_channels] / summed[..., head_channels:]  # [H, N, K, d]
    attended = attended.permute(2, 1, 0, 3).reshape(horizons, -1, channels)  # [K, N, C]
    conditioned = tokens + module.output(attended)
    conditioned = conditioned + module.feed_forward(module.feed_forward_norm(conditioned))
    return conditioned.transpose(1, 2).reshape(horizons, channels, height, width)
