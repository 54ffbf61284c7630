"""The speckle measure (mesh2tex.metrics.spectrum): the share of a texture's power at high spatial frequencies."""

import math

import pytest
import torch

from mesh2tex.metrics.spectrum import high_frequency_share, radial_power, view_pixels_per_unit


def _stripes(period: float, size: int = 64) -> torch.Tensor:
    x = torch.arange(size, dtype=torch.float32)
    return (0.5 + 0.3 * torch.sin(2 * math.pi * x / period)).expand(2, 3, size, size).contiguous()


def test_white_noise_scores_high_and_a_gradient_low():
    masks = torch.ones(2, 1, 64, 64)
    noise = torch.rand(2, 3, 64, 64, generator=torch.Generator().manual_seed(0))
    gradient = torch.linspace(0, 1, 64).expand(2, 3, 64, 64).contiguous()
    assert high_frequency_share(noise, masks, 0.25).share > 0.7  # about the share of the frequency square beyond 1/4
    assert high_frequency_share(gradient, masks, 0.25).share < 0.01
    flat = high_frequency_share(torch.full((2, 3, 64, 64), 0.4), masks, 0.25)
    assert flat.share == 0.0 and flat.total_power == 0.0


def test_a_stripe_patterns_share_follows_its_period():
    masks = torch.ones(2, 1, 64, 64)
    shares = [high_frequency_share(_stripes(p), masks, 0.25).share for p in (2.5, 3.0, 6.0, 10.0, 16.0)]
    assert shares[0] > 0.95 and shares[1] > 0.95  # finer than the cutoff (period 4 px): all its power is high
    assert shares[2] < 0.1 and shares[3] < 0.01 and shares[4] < 0.01  # coarser: none
    assert shares[1:] == sorted(shares[1:], reverse=True)


def test_the_cutoff_in_cycles_per_unit_follows_the_pixels_per_unit():
    """The same stripes seen twice as close (twice the pixels per unit) have the same share at a physical cutoff."""
    masks = torch.ones(2, 1, 64, 64)
    near = high_frequency_share(_stripes(6.0), masks, 20.0, pixels_per_unit=100.0).share  # 16.7 cycles per unit
    far = high_frequency_share(_stripes(3.0), masks, 20.0, pixels_per_unit=50.0).share  # the same 16.7 cycles per unit
    assert near < 0.1 and far < 0.1
    assert high_frequency_share(_stripes(3.0), masks, 20.0, pixels_per_unit=100.0).share > 0.9  # 33 cycles per unit


def test_only_patches_wholly_on_the_object_count():
    """A sharp silhouette over a flat object adds no power: its edge never lies inside a patch."""
    images = torch.ones(1, 3, 64, 64)
    images[..., 8:56, 8:56] = 0.3
    masks = torch.zeros(1, 1, 64, 64)
    masks[..., 8:56, 8:56] = 1
    result = high_frequency_share(images, masks, 0.25, patch=16)
    assert result.patches > 0 and result.total_power < 1e-12 and result.share == 0.0
    assert high_frequency_share(images, torch.zeros(1, 1, 64, 64), 0.25).patches == 0


def test_radial_power_sums_to_one_over_all_frequencies_and_pixels_per_unit():
    masks = torch.ones(2, 1, 64, 64)
    bands = radial_power(_stripes(8.0), masks, [0.0, 0.1, 0.2, 1.0])
    assert float(bands.sum()) == pytest.approx(1.0)
    assert int(bands.argmax()) == 1  # 1/8 cycle per pixel
    assert view_pixels_per_unit(1.0, 90.0, 100) == pytest.approx(50.0)
    with pytest.raises(ValueError, match="pixels_per_unit"):
        high_frequency_share(_stripes(8.0), masks, 20.0, pixels_per_unit=[1.0, 2.0, 3.0])
