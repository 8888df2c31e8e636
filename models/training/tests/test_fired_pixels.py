"""The fired-pixel emphasis of the mask loss: which pixels fired, and how they weigh (that training
takes it: test_training)."""

import numpy as np
import torch

from evgate_train.augment import Augmentation, apply
from evgate_train.losses import bce_dice
from evgate_train.sequence import load_sequence
from evgate_train.windows import FIRED_HALF_SPAN_US, Crop, draw_horizons, reference_input, training_window


def _fired_by_event(sequence, time_us, crop):
    fired = np.zeros((crop.height, crop.width), bool)
    for t, x, y in zip(sequence.events_t, sequence.events_x, sequence.events_y):
        column, row = int(x) - crop.left, int(y) - crop.top
        if time_us - FIRED_HALF_SPAN_US <= t < time_us + FIRED_HALF_SPAN_US and 0 <= column < crop.width and 0 <= row < crop.height:
            fired[row, column] = True
    return fired


def test_fired_pixels_are_the_crop_pixels_with_an_event_near_each_masks_time(synthetic_dir):
    sequence = load_sequence(synthetic_dir / "slide-0.npz")
    crop = Crop(left=30, top=10, height=32, width=48)
    reference = len(sequence.ref_ts) // 2
    horizons = draw_horizons(np.random.default_rng(3), 3)
    window = training_window(
        sequence, reference, crop, horizons, reference_input(sequence, reference), 0, np.random.default_rng(0)
    )
    t = int(sequence.ref_ts[reference])
    np.testing.assert_array_equal(window.fired, _fired_by_event(sequence, t, crop))
    assert window.fired.any() and not window.fired.all()
    for k, horizon in enumerate(horizons):
        np.testing.assert_array_equal(
            window.future_fired[k], _fired_by_event(sequence, t + int(round(horizon * 1000)), crop)
        )
    flipped = apply(window, Augmentation(True, True, False))
    np.testing.assert_array_equal(flipped.fired, window.fired[::-1, ::-1])
    np.testing.assert_array_equal(flipped.future_fired, window.future_fired[:, ::-1, ::-1])


def test_emphasis_weighs_a_pixel_one_plus_its_value_in_the_bce_mean():
    logits = torch.tensor([[[[2.0, -1.0, 0.5]]]])
    target = torch.tensor([[[[0.0, 0.0, 1.0]]]])
    valid = torch.ones_like(target, dtype=torch.bool)
    per_pixel = torch.nn.functional.binary_cross_entropy_with_logits(logits, target, reduction="none").flatten()
    emphasis = torch.tensor([[[[3.0, 0.0, 1.0]]]])
    expected = (4 * per_pixel[0] + per_pixel[1] + 2 * per_pixel[2]) / 7
    torch.testing.assert_close(bce_dice(logits, target, valid, 0.0, 1.0, emphasis), expected)
    torch.testing.assert_close(
        bce_dice(logits, target, valid, 0.0, 1.0, torch.zeros_like(emphasis)), bce_dice(logits, target, valid, 0.0)
    )
    # Invalid pixels stay out whatever their emphasis.
    valid[..., 0] = False
    torch.testing.assert_close(
        bce_dice(logits, target, valid, 0.0, 1.0, emphasis), (per_pixel[1] + 2 * per_pixel[2]) / 3
    )
