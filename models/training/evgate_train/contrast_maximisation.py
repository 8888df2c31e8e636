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


def batched_average_timestamp_loss(
    x: torch.Tensor,
    y: torch.Tensor,
    t_ms: torch.Tensor,
    on: torch.Tensor,
    segment: torch.Tensor,
    velocity: torch.Tensor,
    durations_ms: torch.Tensor,
) -> torch.Tensor:
    """`average_timestamp_loss` of N windows at once, [N]: segment n's loss equals
    `average_timestamp_loss(its events, velocity[n], durations_ms[n])` up to float summation order.

    x, y, t_ms, on as there, of all windows concatenated; segment: long index of each event's
    window in [0, N); velocity [N, 2, H, W]; durations_ms [N] on the same device. A fixed number
    of kernels whatever N, and no host synchronisation: calling the per-window function for each
    window launches hundreds of small kernels per window and reads back a boolean per polarity.
    An absent polarity needs no special case: its images stay zero and add nothing.
    """
    windows, _, height, width = velocity.shape
    pixels = height * width
    pixel = y.long().clamp(0, height - 1) * width + x.long().clamp(0, width - 1)
    event_velocity = velocity.reshape(windows, 2, pixels)[segment, :, pixel]  # [E, 2]
    duration = durations_ms[segment]
    normalised_time = t_ms / duration
    # Reference 0 (window start) then reference `duration` (window end), stacked as rows.
    reference_ms = torch.stack([torch.zeros_like(duration), duration])  # [2, E]
    timestamp = torch.stack([1.0 - normalised_time, normalised_time])
    warped_x = x + (reference_ms - t_ms) * event_velocity[:, 0]
    warped_y = y + (reference_ms - t_ms) * event_velocity[:, 1]
    # One image per (reference, window, polarity), laid out in that order.
    reference = torch.arange(2, device=x.device).view(2, 1)
    image = ((reference * windows + segment) * 2 + (~on).long()) * pixels  # [2, E]
    # The four bilinear corners as a leading axis, [4, 2, E]; offsets made on the device, as a
    # tensor from a Python list would be a blocking host-to-device copy.
    corner = torch.arange(4, device=x.device, dtype=x.dtype).view(4, 1, 1)
    corner_x = torch.floor(warped_x) + corner % 2
    corner_y = torch.floor(warped_y) + torch.div(corner, 2, rounding_mode="floor")
    kernel = (1.0 - (warped_x - corner_x).abs()) * (1.0 - (warped_y - corner_y).abs())
    inside = (corner_x >= 0) & (corner_x <= width - 1) & (corner_y >= 0) & (corner_y <= height - 1)
    index = image + (corner_y.clamp(0, height - 1) * width + corner_x.clamp(0, width - 1)).long()
    weight = kernel * inside.to(kernel.dtype)
    images = 2 * windows * 2 * pixels
    # Event counts in the first `images` entries, timestamp sums in the next: one 1-D index_add
    # (the CPU index_add over rows of a 2-D image runs one tensor operation per index; scatter_add
    # splats faster on CPU but its backward, a gather, costs more than it saves).
    splat = weight.new_zeros(2 * images).index_add(
        0,
        torch.cat([index.reshape(-1), (index + images).reshape(-1)]),
        torch.cat([weight.reshape(-1), (weight * timestamp).reshape(-1)]),
    )
    # unbind, not slicing: each slice's backward would fill a zero gradient of the whole splat.
    counts, stamps = splat.view(2, 2, windows, 2, pixels).unbind(0)
    average = stamps / (counts + 1e-9)
    loss = (average**2).sum(dim=(2, 3))  # [2, N]
    hit = (counts.sum(dim=2) > 0).sum(dim=2).to(x.dtype)
    return (loss / (hit + 1e-9)).sum(dim=0)
