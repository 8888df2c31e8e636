"""Unsupervised contrast maximisation on the future window's events.

Events of [t, t + h] are transported along the predicted velocity to the window's start and
to its end, x' = x + (t_ref - t_i) v(x_i), and splatted bilinearly into images of warped
events per polarity. The focus measure is the average-timestamp loss of Paredes-Vallés et al.
(2021): at each pixel, the mean of the events' normalised timestamps (towards the reference
time) squared, summed over pixels and divided by the number of pixels hit. Sharp images, where
an edge's events from all times land on one pixel, mix early and late timestamps and score
lower than motion-blurred ones, whose leading and trailing pixels hold only late or early
events. The measure is scale-free, so it stays comparable across event counts. Events pushed
out of the image no longer count, which a degenerate flow could exploit: the supervised flow
and future-mask terms keep the flow anchored, as in the paper's hybrid loss.
"""

import torch


def _splat(x: torch.Tensor, y: torch.Tensor, weights: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """Bilinear splat of weights at real positions (x, y) into an image [height * width]."""
    image = weights.new_zeros(height * width)
    x0, y0 = torch.floor(x), torch.floor(y)
    for dx in (0.0, 1.0):
        for dy in (0.0, 1.0):
            cx, cy = x0 + dx, y0 + dy
            kernel = (1.0 - (x - cx).abs()) * (1.0 - (y - cy).abs())
            inside = (cx >= 0) & (cx <= width - 1) & (cy >= 0) & (cy <= height - 1)
            index = (cy.clamp(0, height - 1) * width + cx.clamp(0, width - 1)).long()
            image = image.index_add(0, index, weights * kernel * inside.to(weights.dtype))
    return image


def average_timestamp_loss(
    x: torch.Tensor,
    y: torch.Tensor,
    t_ms: torch.Tensor,
    on: torch.Tensor,
    velocity: torch.Tensor,
    duration_ms: float,
) -> torch.Tensor:
    """Loss of one window's events under velocity [2, H, W] (px/ms).

    x, y: event pixel coordinates (float); t_ms: time since the window start in ms, in
    [0, duration_ms]; on: bool polarity. Lower is sharper.
    """
    _, height, width = velocity.shape
    pixel = (y.long().clamp(0, height - 1) * width + x.long().clamp(0, width - 1))
    vx = velocity[0].reshape(-1)[pixel]
    vy = velocity[1].reshape(-1)[pixel]
    normalised_time = t_ms / duration_ms
    total = x.new_zeros(())
    for reference_ms, timestamp in ((0.0, 1.0 - normalised_time), (duration_ms, normalised_time)):
        warped_x = x + (reference_ms - t_ms) * vx
        warped_y = y + (reference_ms - t_ms) * vy
        loss = x.new_zeros(())
        hit = x.new_zeros(height * width)
        for polarity in (on, ~on):
            if not bool(polarity.any()):
                continue
            counts = _splat(warped_x[polarity], warped_y[polarity], torch.ones_like(x[polarity]), height, width)
            stamps = _splat(warped_x[polarity], warped_y[polarity], timestamp[polarity], height, width)
            average = stamps / (counts + 1e-9)
            loss = loss + (average**2).sum()
            hit = hit + counts
        total = total + loss / ((hit > 0).sum().to(x.dtype) + 1e-9)
    return total
