"""Sliced Wasserstein distance between two image sets on Laplacian-pyramid patches (needs no weights).

As in Karras et al. (Progressive GANs): each image is decomposed into a Laplacian pyramid (5-tap
binomial filter) down to 16 pixels; from every level, ``patches_per_image`` random 7 x 7 x 3
neighbourhoods are taken as descriptors; the sliced Wasserstein distance between the two sets of
descriptors is the mean, over ``num_projections`` random unit directions, of the mean absolute
difference of the sorted projections. Small values mean the sets have similar local structure at
that scale.

One deliberate difference: descriptors of both sets are normalised per channel with the mean and
standard deviation of set A (the reference), not each set with its own statistics, so a global
colour or contrast change of set B raises the distance instead of being normalised away.
Reported values are multiplied by 1000, as is customary.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from mesh2tex.checks import check_shape

_BINOMIAL = torch.tensor([1.0, 4.0, 6.0, 4.0, 1.0]) / 16.0


def to_unit_range(images_a: torch.Tensor, images_b: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Both sets to [0, 1]: sets with any negative value are taken as [-1, 1] (both the same way)."""
    signed = bool(images_a.min() < 0) or bool(images_b.min() < 0)
    if signed:
        return (images_a.float() + 1) / 2, (images_b.float() + 1) / 2
    return images_a.float(), images_b.float()


def _blur(images: torch.Tensor) -> torch.Tensor:
    kernel = (_BINOMIAL[:, None] * _BINOMIAL[None, :]).to(images)
    channels = images.shape[1]
    weight = kernel.expand(channels, 1, 5, 5)
    return F.conv2d(F.pad(images, (2, 2, 2, 2), mode="reflect"), weight, groups=channels)


def laplacian_pyramid(images: torch.Tensor, min_size: int = 16) -> list[torch.Tensor]:
    """Laplacian pyramid of images [N, C, H, W]: band-pass levels from full resolution down, then the
    low-pass residual of side >= ``min_size``. Returns a list of [N, C, H / 2^l, W / 2^l]."""
    check_shape(images, "laplacian_pyramid: images", ("N", "C", "H", "W"), dtype="float")
    levels = []
    current = images
    while min(current.shape[-2:]) // 2 >= min_size:
        down = _blur(current)[..., ::2, ::2]
        up = F.interpolate(down, size=current.shape[-2:], mode="bilinear", align_corners=False)
        levels.append(current - up)
        current = down
    levels.append(current)
    return levels


def _descriptors(
    level: torch.Tensor, patches_per_image: int, patch_size: int, generator: torch.Generator
) -> torch.Tensor:
    """Random patch_size^2 * C neighbourhoods: [N * patches_per_image, C * patch_size^2]."""
    count, channels, height, width = level.shape
    rows = torch.randint(height - patch_size + 1, (count, patches_per_image), generator=generator)
    cols = torch.randint(width - patch_size + 1, (count, patches_per_image), generator=generator)
    offsets = torch.arange(patch_size)
    row_index = (rows[..., None, None] + offsets[:, None]).expand(-1, -1, patch_size, patch_size)
    col_index = (cols[..., None, None] + offsets[None, :]).expand(-1, -1, patch_size, patch_size)
    image_index = torch.arange(count)[:, None, None, None].expand_as(row_index)
    patches = level.permute(0, 2, 3, 1)[image_index, row_index, col_index]  # [N, P, k, k, C]
    return patches.reshape(count * patches_per_image, -1)


def sliced_wasserstein(
    descriptors_a: torch.Tensor, descriptors_b: torch.Tensor, num_projections: int, generator: torch.Generator
) -> float:
    """Sliced Wasserstein-1 distance between two point sets [M, D] (equal M): mean over random directions."""
    sizes = check_shape(descriptors_a, "sliced_wasserstein: descriptors_a", ("M", "D"), dtype="float")
    check_shape(descriptors_b, "sliced_wasserstein: descriptors_b", ("M", "D"), sizes=sizes, dtype="float")
    directions = torch.randn(descriptors_a.shape[1], num_projections, generator=generator, dtype=descriptors_a.dtype)
    directions = directions / directions.norm(dim=0, keepdim=True)
    projected_a = sorted_rows(directions.T @ descriptors_a.T)
    projected_b = sorted_rows(directions.T @ descriptors_b.T)
    return float((projected_a - projected_b).abs().mean())


def sorted_rows(values: torch.Tensor) -> torch.Tensor:
    """``values`` [P, M] (CPU) with each row sorted ascending, the same numbers as ``torch.sort(values, dim=1).values``.

    numpy sorts these float64 rows about 2.5 times faster than torch on the CPU (its vectorised
    quicksort on one thread, against torch's on two), and sorting is where the SWD spends most of
    its time (``benchmarks/bench_swd.py``). Rows along the last, contiguous axis: torch sorts along
    the first several times slower.
    """
    check_shape(values, "sorted_rows: values", ("P", "M"))
    return torch.from_numpy(np.sort(values.detach().contiguous().numpy(), axis=1))


def _check_sets(function: str, images_a: torch.Tensor, images_b: torch.Tensor) -> None:
    """images_a [N, 3, H, W] and images_b [M, 3, H, W] float, named ``function: images_a`` / ``images_b``."""
    sizes = check_shape(images_a, f"{function}: images_a", ("N", 3, "H", "W"), dtype="float")
    check_shape(images_b, f"{function}: images_b", ("M", 3, "H", "W"), sizes=sizes, dtype="float")


def swd_per_level(
    images_a: torch.Tensor,
    images_b: torch.Tensor,
    patches_per_image: int = 128,
    patch_size: int = 7,
    num_projections: int = 512,
    repeats: int = 4,
    seed: int = 0,
) -> dict[str, float]:
    """SWD x 1000 per pyramid level and their average.

    images_a (reference), images_b: [N, 3, H, W] and [M, 3, H, W] in [0, 1] or [-1, 1] (see
    :func:`to_unit_range`), same H, W (>= 16). Descriptor sets are subsampled to equal size.
    Returns {"swd_<side>px": value for each level (finest first), "swd": average}.
    """
    _check_sets("swd_per_level", images_a, images_b)
    generator = torch.Generator().manual_seed(seed)
    images_a, images_b = to_unit_range(images_a.detach().cpu(), images_b.detach().cpu())
    result = {}
    for level_a, level_b in zip(laplacian_pyramid(images_a), laplacian_pyramid(images_b)):
        size = min(patch_size, *level_a.shape[-2:])
        desc_a = _descriptors(level_a, patches_per_image, size, generator).double()
        desc_b = _descriptors(level_b, patches_per_image, size, generator).double()
        channels = level_a.shape[1]
        # Per-channel statistics of the reference set normalise both sets.
        by_channel = desc_a.reshape(desc_a.shape[0], -1, channels)
        mean = by_channel.mean(dim=(0, 1)).repeat(desc_a.shape[1] // channels)
        std = by_channel.std(dim=(0, 1)).clamp_min(1e-8).repeat(desc_a.shape[1] // channels)
        desc_a, desc_b = (desc_a - mean) / std, (desc_b - mean) / std
        count = min(desc_a.shape[0], desc_b.shape[0])
        desc_a = desc_a[torch.randperm(desc_a.shape[0], generator=generator)[:count]]
        desc_b = desc_b[torch.randperm(desc_b.shape[0], generator=generator)[:count]]
        value = sum(sliced_wasserstein(desc_a, desc_b, num_projections, generator) for _ in range(repeats)) / repeats
        result[f"swd_{level_a.shape[-1]}px"] = 1000.0 * value
    result["swd"] = sum(result.values()) / len(result)
    return result


def swd(images_a: torch.Tensor, images_b: torch.Tensor, **options) -> float:
    """Sliced Wasserstein distance x 1000 between image sets [N, 3, H, W] in [0, 1] or [-1, 1],
    averaged over Laplacian-pyramid levels (see :func:`swd_per_level` for the options). Lower is closer;
    about 0 (up to sampling noise) for two samples of one distribution."""
    _check_sets("swd", images_a, images_b)
    return swd_per_level(images_a, images_b, **options)["swd"]
