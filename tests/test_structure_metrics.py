"""The independent judge of texture structure: orientation coherence and ratio, period, regularity, patch distance."""

import math

import numpy as np
import pytest
import torch

from mesh2tex.metrics.structure import (
    orientation_scores,
    orientation_windows,
    patch_swd,
    regularity,
    spectrum_period,
    structure_scores,
)
from mesh2tex.synthetic.exemplars import exemplar_image


def _grey(values: np.ndarray) -> torch.Tensor:
    """(H, W) in [0, 1] -> (1, 3, H, W) float64."""
    return torch.from_numpy(values).double()[None, None].expand(1, 3, *values.shape).clone()


def _stripes(angle_degrees: float, period: float = 12.0, size: int = 96) -> torch.Tensor:
    """Smooth stripes whose bands run at ``angle_degrees`` (their gradient at angle + 90)."""
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    a = math.radians(angle_degrees + 90.0)
    return _grey(0.5 + 0.4 * np.sin(2 * math.pi * (x * math.cos(a) + y * math.sin(a)) / period))


def _checker(square: int = 8, size: int = 96) -> torch.Tensor:
    y, x = np.mgrid[0:size, 0:size]
    return _grey(np.where((x // square + y // square) % 2 == 0, 0.2, 0.8).astype(np.float64))


def _exemplar(name: str) -> torch.Tensor:
    return torch.from_numpy(exemplar_image(name, 128)).permute(2, 0, 1)[None].double() / 255


def test_stripes_are_coherent_and_have_no_perpendicular_energy():
    scores = structure_scores(_stripes(30.0))
    assert scores.coherence > 0.95
    assert scores.ratio < 0.1
    assert scores.windows > 0


def test_a_checker_has_two_equal_perpendicular_directions():
    scores = structure_scores(_checker(), window=32)
    assert scores.ratio > 0.9
    assert scores.coherence < 0.2


@pytest.mark.parametrize("angle", [0.0, 30.0, 75.0, 120.0])
def test_the_dominant_direction_turns_with_the_stripes(angle):
    direction = math.degrees(structure_scores(_stripes(angle)).direction)
    expected = (angle + 90.0) % 180.0  # the gradient is across the bands
    assert min(abs(direction - expected), 180 - abs(direction - expected)) < 3.0


@pytest.mark.parametrize("period", [8.0, 12.0, 16.0])
def test_the_period_of_a_known_pattern_is_found(period):
    assert spectrum_period(_stripes(20.0, period=period)) == pytest.approx(period, rel=0.06)


def test_a_flat_colour_has_no_windows_and_no_period():
    flat = _grey(np.full((64, 64), 0.4))
    histograms, doubled = orientation_windows(flat)
    assert len(histograms) == 0 and len(doubled) == 0
    assert all(math.isnan(v) for v in orientation_scores(histograms, doubled))
    assert math.isnan(spectrum_period(flat))


def test_only_object_pixels_count():
    image = _stripes(30.0)
    mask = torch.zeros(1, 1, 96, 96, dtype=torch.float64)
    mask[..., 20:76, 20:76] = 1
    noisy = image.clone()
    noisy[..., mask[0, 0] < 0.5] = torch.rand(
        3, int((mask < 0.5).sum()), generator=torch.Generator().manual_seed(0), dtype=torch.float64
    )
    a, b = structure_scores(image, mask, _exemplar("stripes")), structure_scores(noisy, mask, _exemplar("stripes"))
    assert a.as_dict() == b.as_dict()


@pytest.mark.parametrize("name", ["stripes", "checker", "dots"])
def test_the_oracle_beats_flat_colour_and_noise(name):
    """The exemplar's own pattern (shifted by a few pixels, seen through a disc) is closer to it than
    its flat mean colour and than per-pixel noise of its colours."""
    exemplar = _exemplar(name)
    yy, xx = torch.meshgrid(torch.arange(128), torch.arange(128), indexing="ij")
    mask = (((yy - 64) ** 2 + (xx - 64) ** 2) < 56**2).double()[None, None]
    oracle = torch.roll(exemplar, shifts=(5, 9), dims=(2, 3))
    flat = exemplar.mean(dim=(2, 3), keepdim=True).expand_as(exemplar)
    pick = torch.randint(128 * 128, (128 * 128,), generator=torch.Generator().manual_seed(1))
    noise = exemplar.flatten(2)[:, :, pick].reshape(exemplar.shape)
    own = patch_swd(oracle, mask, exemplar, turns=False)
    assert own < 0.5 * patch_swd(flat, mask, exemplar, turns=False)
    assert own < 0.5 * patch_swd(noise, mask, exemplar, turns=False)
    # Against every orientation of the exemplar (as meshes are judged) the ranking holds too.
    turned = patch_swd(oracle, mask, exemplar)
    assert turned < patch_swd(flat, mask, exemplar) and turned < patch_swd(noise, mask, exemplar)


def test_a_masked_reference_gives_only_its_objects_patches():
    """Against renders with masks (the oracle's, as the structure benchmark compares with them), the patches off
    the reference's object do not count: its background changed to anything leaves the distance as it was, and
    the pattern moved scores far closer than its flat colour."""
    exemplar = _exemplar("checker")
    yy, xx = torch.meshgrid(torch.arange(128), torch.arange(128), indexing="ij")
    disc = (((yy - 64) ** 2 + (xx - 64) ** 2) < 50**2).double()[None, None]
    reference = torch.where(disc > 0.5, exemplar, torch.ones_like(exemplar))
    other_background = torch.where(disc > 0.5, exemplar, torch.zeros_like(exemplar))
    moved = torch.roll(exemplar, shifts=(7, 3), dims=(2, 3))
    flat = exemplar.mean(dim=(2, 3), keepdim=True).expand_as(exemplar)
    own = patch_swd(moved, disc, reference, turns=False, exemplar_masks=disc)
    assert own == patch_swd(moved, disc, other_background, turns=False, exemplar_masks=disc)
    assert own < 0.3 * patch_swd(flat, disc, reference, turns=False, exemplar_masks=disc)
    # Without the reference's mask its white background counts, and the distance changes.
    assert patch_swd(moved, disc, reference, turns=False) != own


def _blotches(seed: int = 0, size: int = 96) -> torch.Tensor:
    """Two grey levels in random blobs about as large as the checker's squares: isotropic, no repeat."""
    noise = torch.rand(1, 1, size + 8, size + 8, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    smooth = torch.nn.functional.avg_pool2d(noise, 9, stride=1)
    return torch.where(smooth > smooth.median(), 0.8, 0.2).expand(1, 3, size, size).clone()


def test_regularity_tells_a_repeating_pattern_from_blotches():
    """Checks and stripes repeat (near 1), even softened; blotches of the same two colours and noise do not
    (near 0), although the blotches' orientation ratio is as high as the checker's."""
    soft_checker = torch.nn.functional.avg_pool2d(torch.nn.functional.pad(_checker(), (2, 2, 2, 2), "reflect"), 5, 1)
    assert regularity(_checker()) > 0.9
    assert regularity(_stripes(30.0)) > 0.9
    assert regularity(soft_checker) > 0.8
    for name in ("checker", "stripes", "bricks", "dots"):
        assert regularity(_exemplar(name)) > 0.9, name
    blotches = _blotches()
    assert regularity(blotches) < 0.3
    assert regularity(torch.rand(1, 3, 96, 96, generator=torch.Generator().manual_seed(1), dtype=torch.float64)) < 0.2
    assert structure_scores(blotches).ratio > 0.5  # what the orientation ratio cannot tell


def test_regularity_reads_only_the_object_and_is_nan_for_a_flat_colour():
    checker = _checker()
    yy, xx = torch.meshgrid(torch.arange(96), torch.arange(96), indexing="ij")
    mask = (((yy - 48) ** 2 + (xx - 48) ** 2) < 40**2).double()[None, None]
    other = checker.clone()
    other[..., mask[0, 0] < 0.5] = torch.rand(
        int((mask < 0.5).sum()), generator=torch.Generator().manual_seed(2)
    ).double()
    assert regularity(checker, mask) == pytest.approx(regularity(other, mask), abs=1e-12)
    assert math.isnan(regularity(torch.full((1, 3, 32, 32), 0.5, dtype=torch.float64)))
