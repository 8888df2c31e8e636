import torch

from evgate_train.warp import backward_warp, backward_warp_normalised, normalising_scale


def test_mask_moved_by_a_known_flow_lands_where_expected():
    mask = torch.zeros(1, 1, 20, 30)
    mask[0, 0, 5:9, 4:8] = 1.0
    flow = torch.zeros(1, 2, 20, 30)
    flow[:, 0], flow[:, 1] = 6.0, -2.0  # 6 px right, 2 px up
    moved = backward_warp(mask, flow)
    expected = torch.zeros(1, 1, 20, 30)
    expected[0, 0, 3:7, 10:14] = 1.0
    torch.testing.assert_close(moved, expected)


def test_fractional_flow_interpolates_and_outside_is_zero():
    image = torch.arange(5.0).view(1, 1, 1, 5).expand(1, 1, 3, 5).contiguous()
    flow = torch.zeros(1, 2, 3, 5)
    flow[:, 0] = 0.5
    moved = backward_warp(image, flow)
    # x = 2 samples at 1.5 -> 1.5; x = 0 samples at -0.5: half outside (zero) -> 0.
    assert abs(float(moved[0, 0, 1, 2]) - 1.5) < 1e-6
    assert abs(float(moved[0, 0, 1, 0]) - 0.0) < 1e-6


def test_normalised_warp_samples_where_the_pixel_warp_does():
    generator = torch.Generator().manual_seed(2)
    image = torch.randn(3, 1, 20, 30, generator=generator)
    flow = 6.0 * torch.randn(3, 2, 20, 30, generator=generator)
    moved = backward_warp_normalised(image, flow * normalising_scale(20, 30))
    torch.testing.assert_close(moved, backward_warp(image, flow), atol=1e-4, rtol=0)
