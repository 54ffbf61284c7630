"""Appearance metrics a person would agree with: right colours on the right parts, in the right places.

Images are [B, 3, H, W] float sRGB in [0, 1]; masks [B, 1, H, W] in {0, 1}; part maps [B, H, W]
int64 part labels (any integers; negative values are "no part"). Every function returns one value
per image pair, [B] float64, like :mod:`mesh2tex.metrics.image`.

* :func:`part_colour_error`: the mean CIELAB colour of each part (seat, back, leg ...) in the image
  and in the reference, their distance (CIE76 ΔE), averaged over the parts weighted by pixel count.
  Texture phase does not matter, a wrong colour on the wrong part does. The two images need not
  share their geometry: each has its own part map and mask (transfer to another shape).
* :func:`lowpass_psnr`: PSNR of both images after a Gaussian blur of the object pixels alone
  (normalised convolution, so the background never bleeds in): colours in the right places count,
  the exact position of stripes and checks does not.
* :func:`object_swd`: sliced Wasserstein distance between the 7x7 patches of the two images' object
  pixels, level by level of a Laplacian pyramid: texture statistics, no alignment needed.
"""

from __future__ import annotations

import math

import kornia
import torch
import torch.nn.functional as F

from mesh2tex.checks import check_shape
from mesh2tex.metrics.swd import laplacian_pyramid, sliced_wasserstein
from mesh2tex.render.shading import composite_images


def _check_pair(
    function: str,
    images: torch.Tensor,
    masks: torch.Tensor | None,
    references: torch.Tensor | None = None,
    reference_masks: torch.Tensor | None = None,
    mask_needed: bool = True,
) -> dict:
    """images [B, 3, H, W] float with masks [B, 1, H, W]; references [B, 3, H', W'] with reference_masks
    [B, 1, H', W'] (the images' H, W when reference_masks is None). Returns the sizes, for further checks."""
    sizes = check_shape(images, f"{function}: images", ("B", 3, "H", "W"), dtype="float")
    check_shape(masks, f"{function}: masks", ("B", 1, "H", "W"), sizes=sizes, optional=not mask_needed)
    if references is not None:
        own = "H" if reference_masks is None else "H'"
        check_shape(
            references, f"{function}: references", ("B", 3, own, own.replace("H", "W")), sizes=sizes, dtype="float"
        )
        check_shape(reference_masks, f"{function}: reference_masks", ("B", 1, "H'", "W'"), sizes=sizes, optional=True)
    return sizes


def rgb_to_lab(images: torch.Tensor) -> torch.Tensor:
    """[B, 3, H, W] sRGB in [0, 1] -> CIELAB (D65) [B, 3, H, W] float64: L in [0, 100], a and b about [-128, 127]."""
    check_shape(images, "rgb_to_lab: images", ("B", 3, "H", "W"), dtype="float")
    return kornia.color.rgb_to_lab(images.float().clamp(0, 1)).double()


def part_colours(
    images: torch.Tensor, parts: torch.Tensor, masks: torch.Tensor | None = None, min_pixels: int = 4
) -> list[dict[int, tuple[torch.Tensor, int]]]:
    """Per image, {part label: (mean CIELAB colour [3] float64, pixel count)} of the parts with at
    least ``min_pixels`` pixels inside ``masks`` (None: every pixel with a label >= 0). images [B, 3, H, W]
    in [0, 1]; parts [B, H, W] integer labels; masks [B, 1, H, W] or None."""
    sizes = _check_pair("part_colours", images, masks, mask_needed=False)
    check_shape(parts, "part_colours: parts", ("B", "H", "W"), sizes=sizes, dtype="int")
    lab = rgb_to_lab(images)
    valid = parts >= 0
    if masks is not None:
        valid = valid & (masks[:, 0] > 0.5)
    result = []
    for b in range(images.shape[0]):
        colours = {}
        for label in torch.unique(parts[b][valid[b]]).tolist():
            where = valid[b] & (parts[b] == label)
            count = int(where.sum())
            if count >= min_pixels:
                colours[int(label)] = (lab[b][:, where].mean(dim=1), count)
        result.append(colours)
    return result


def part_colour_error(
    images: torch.Tensor,
    references: torch.Tensor,
    parts: torch.Tensor,
    masks: torch.Tensor | None = None,
    reference_parts: torch.Tensor | None = None,
    reference_masks: torch.Tensor | None = None,
    min_pixels: int = 4,
) -> torch.Tensor:
    """Per-part colour error ΔE (CIE76, CIELAB units; about 2.3 is a just-noticeable difference): [B] float64.

    For each part label seen (``min_pixels`` or more) in both the image and the reference, the
    distance between their mean CIELAB colours; the mean of these distances weighted by the part's
    pixel count in the reference. ``reference_parts`` / ``reference_masks`` default to ``parts`` /
    ``masks`` (pixel-aligned images of one geometry). NaN when no part is seen in both. images [B, 3, H, W]
    with parts [B, H, W] and masks [B, 1, H, W] or None; references [B, 3, H', W'] with reference_parts
    [B, H', W'] and reference_masks [B, 1, H', W'] (H', W' = H, W when they default to the images' own).
    """
    sizes = _check_pair("part_colour_error", images, masks, mask_needed=False)
    check_shape(parts, "part_colour_error: parts", ("B", "H", "W"), sizes=sizes, dtype="int")
    own = "H'" if reference_parts is not None and (reference_masks is not None or masks is None) else "H"  # own size
    check_shape(
        references, "part_colour_error: references", ("B", 3, own, own.replace("H", "W")), sizes=sizes, dtype="float"
    )
    check_shape(
        reference_parts,
        "part_colour_error: reference_parts",
        ("B", own, own.replace("H", "W")),
        sizes=sizes,
        dtype="int",
        optional=True,
    )
    check_shape(
        reference_masks,
        "part_colour_error: reference_masks",
        ("B", 1, own, own.replace("H", "W")),
        sizes=sizes,
        optional=True,
    )
    reference_parts = parts if reference_parts is None else reference_parts
    reference_masks = masks if reference_masks is None else reference_masks
    mine = part_colours(images, parts, masks, min_pixels)
    theirs = part_colours(references, reference_parts, reference_masks, min_pixels)
    errors = []
    for a, b in zip(mine, theirs):
        shared = sorted(set(a) & set(b))
        weight = sum(b[p][1] for p in shared)
        errors.append(sum(float((a[p][0] - b[p][0]).norm()) * b[p][1] for p in shared) / weight if weight else math.nan)
    return torch.tensor(errors, dtype=torch.float64)


def gaussian_kernel(sigma: float) -> torch.Tensor:
    """1-D Gaussian of standard deviation ``sigma`` pixels, radius ceil(3 sigma), summing to 1: [2r+1] float64."""
    radius = max(1, math.ceil(3 * sigma))
    x = torch.arange(-radius, radius + 1, dtype=torch.float64)
    kernel = torch.exp(-0.5 * (x / sigma) ** 2)
    return kernel / kernel.sum()


def masked_blur(images: torch.Tensor, masks: torch.Tensor, sigma: float) -> torch.Tensor:
    """Gaussian blur (``sigma`` pixels) of the masked pixels only: blur(image * mask) / blur(mask).

    images [B, C, H, W], masks [B, 1, H, W] -> [B, C, H, W] float64; 0 where no masked pixel is near.
    """
    sizes = check_shape(images, "masked_blur: images", ("B", "C", "H", "W"), dtype="float")
    check_shape(masks, "masked_blur: masks", ("B", 1, "H", "W"), sizes=sizes)
    if sigma <= 0:
        return images.double() * masks
    kernel = gaussian_kernel(sigma).to(images.device)
    r = kernel.numel() // 2
    channels = images.shape[1] + 1
    stacked = torch.cat([images.double() * masks, masks.double()], dim=1)
    stacked = F.conv2d(
        F.pad(stacked, (r, r, 0, 0)), kernel.reshape(1, 1, 1, -1).expand(channels, 1, 1, -1), groups=channels
    )
    stacked = F.conv2d(
        F.pad(stacked, (0, 0, r, r)), kernel.reshape(1, 1, -1, 1).expand(channels, 1, -1, 1), groups=channels
    )
    weight = stacked[:, -1:]
    return torch.where(weight > 1e-6, stacked[:, :-1] / weight.clamp_min(1e-6), torch.zeros_like(stacked[:, :-1]))


def lowpass_psnr(
    images: torch.Tensor, references: torch.Tensor, masks: torch.Tensor, sigma: float = 3.0
) -> torch.Tensor:
    """PSNR in dB (peak 1) over ``masks`` after a Gaussian blur of ``sigma`` pixels of each image's
    masked pixels (:func:`masked_blur`, with the same mask for both): [B] float64; +inf if equal.
    images and references [B, 3, H, W] in [0, 1], masks [B, 1, H, W]."""
    _check_pair("lowpass_psnr", images, masks, references)
    a, b = masked_blur(images, masks, sigma), masked_blur(references, masks, sigma)
    weights = masks.double()
    mse = ((a - b) ** 2 * weights).sum(dim=(1, 2, 3)) / (weights.sum(dim=(1, 2, 3)) * images.shape[1])
    return 10.0 * torch.log10(1.0 / mse)


def _object_patches(
    level: torch.Tensor, mask: torch.Tensor, count: int, patch: int, generator: torch.Generator
) -> torch.Tensor:
    """Up to ``count`` random patch x patch neighbourhoods centred on mask pixels of one image: [n, C*patch^2]."""
    _, channels, height, width = level.shape
    r = patch // 2
    padded = F.pad(level, (r, r, r, r), mode="replicate")
    rows, cols = torch.nonzero(mask[0, 0] > 0.5, as_tuple=True)
    if rows.numel() == 0:
        return level.new_zeros(0, channels * patch * patch)
    pick = torch.randperm(rows.numel(), generator=generator)[:count]
    rows, cols = rows[pick], cols[pick]
    offsets = torch.arange(patch)
    row_index = (rows[:, None, None] + offsets[None, :, None]).expand(-1, patch, patch)
    col_index = (cols[:, None, None] + offsets[None, None, :]).expand(-1, patch, patch)
    patches = padded[0].permute(1, 2, 0)[row_index, col_index]  # [n, patch, patch, C]
    return patches.reshape(rows.numel(), -1)


def _fill_background(image: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """[1, C, H, W]: the pixels off ``mask`` set to the mean object colour, so no pyramid level sees the background."""
    weight = mask.sum().clamp_min(1.0)
    mean = (image * mask).sum(dim=(2, 3), keepdim=True) / weight
    return composite_images(image, mask, mean)


def object_swd(
    images: torch.Tensor,
    references: torch.Tensor,
    masks: torch.Tensor,
    reference_masks: torch.Tensor | None = None,
    patches: int = 256,
    patch_size: int = 7,
    projections: int = 256,
    min_size: int = 16,
    seed: int = 0,
) -> torch.Tensor:
    """Sliced Wasserstein distance x 1000 between the object patches of each image and its reference: [B] float64.

    Off each image's mask, pixels take its mean object colour (the background never enters); both
    images are split into Laplacian pyramids (down to ``min_size`` pixels); at every level up
    to ``patches`` random ``patch_size`` neighbourhoods centred on object pixels (the mask taken down
    with the level) are drawn from each, normalised per channel by the reference's statistics, and
    compared with ``projections`` random directions (the same for every image: a fixed ``seed``
    makes paired comparisons of methods share their noise). The value averages the levels with at
    least 8 patches on both sides; NaN if none has. images [B, 3, H, W] with masks [B, 1, H, W];
    references [B, 3, H', W'] with reference_masks [B, 1, H', W'], which default to ``masks`` (then H', W' = H, W).
    """
    _check_pair("object_swd", images, masks, references, reference_masks)
    reference_masks = masks if reference_masks is None else reference_masks
    values = []
    for b in range(images.shape[0]):
        generator = torch.Generator().manual_seed(seed)
        mask_a, mask_b = reference_masks[b : b + 1].double(), masks[b : b + 1].double()
        levels_a = laplacian_pyramid(_fill_background(references[b : b + 1].double(), mask_a), min_size)
        levels_b = laplacian_pyramid(_fill_background(images[b : b + 1].double(), mask_b), min_size)
        per_level = []
        for level_a, level_b in zip(levels_a, levels_b):
            size = level_a.shape[-2:]
            m_a = F.interpolate(mask_a, size=size, mode="area") if mask_a.shape[-2:] != size else mask_a
            m_b = F.interpolate(mask_b, size=size, mode="area") if mask_b.shape[-2:] != size else mask_b
            k = min(patch_size, *size) | 1
            desc_a = _object_patches(level_a, m_a, patches, k, generator)
            desc_b = _object_patches(level_b, m_b, patches, k, generator)
            n = min(desc_a.shape[0], desc_b.shape[0])
            if n < 8:
                continue
            channels = level_a.shape[1]
            by_channel = desc_a.reshape(desc_a.shape[0], -1, channels)
            mean = by_channel.mean(dim=(0, 1)).repeat(desc_a.shape[1] // channels)
            std = by_channel.std(dim=(0, 1)).clamp_min(1e-8).repeat(desc_a.shape[1] // channels)
            desc_a, desc_b = ((desc_a - mean) / std)[:n], ((desc_b - mean) / std)[:n]
            per_level.append(1000.0 * sliced_wasserstein(desc_a, desc_b, projections, generator))
        values.append(sum(per_level) / len(per_level) if per_level else math.nan)
    return torch.tensor(values, dtype=torch.float64)
