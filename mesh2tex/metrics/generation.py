"""Measures of a texture generator beyond distribution distance: colour diversity across latents and
the share of the untrained-to-oracle gap a trained generator closes.

All colours are CIELAB (D65, from sRGB in [0, 1], kornia's conversion), so distances are Delta E
(CIE76): about 2.3 is a just noticeable difference.

    mean_object_lab        mean Lab colour of each image's object pixels
    colour_spread          sqrt(trace(cov)) of a set of mean colours: how far apart the sampled
                           textures' overall colours lie (0 for a generator that ignores its latent)
    mean_pairwise_delta_e  mean over pairs of images of one shape at one pose of the per-pixel
                           Delta E on the object: differences in pattern and part colours as well
    gap_closed             (log d_untrained - log d_trained) / (log d_untrained - log d_oracle)
    object_set_swd         sliced Wasserstein distance between the object patches of two image sets
                           (unpaired): texture and colour statistics with the background and the
                           silhouettes left out, so that renders of other shapes compare fairly
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from kornia.color import rgb_to_lab

from mesh2tex.checks import check_shape
from mesh2tex.metrics.appearance import _fill_background, _object_patches
from mesh2tex.metrics.swd import laplacian_pyramid, sliced_wasserstein


def srgb_to_lab(images: torch.Tensor) -> torch.Tensor:
    """images (N, 3, H, W) sRGB in [0, 1] -> (N, 3, H, W) CIELAB (L in [0, 100])."""
    check_shape(images, "srgb_to_lab: images", ("N", 3, "H", "W"), dtype="float")
    return rgb_to_lab(images.float().clamp(0, 1))


def mean_object_lab(images: torch.Tensor, masks: torch.Tensor) -> torch.Tensor:
    """images (N, 3, H, W) in [0, 1], masks (N, 1, H, W) 0/1 -> (N, 3) mean Lab of the object pixels.

    Raises ValueError when an image has no object pixel.
    """
    sizes = check_shape(images, "mean_object_lab: images", ("N", 3, "H", "W"), dtype="float")
    check_shape(masks, "mean_object_lab: masks", ("N", 1, "H", "W"), sizes=sizes)
    weight = masks.float()
    area = weight.sum(dim=[1, 2, 3])
    if (area <= 0).any():
        raise ValueError(f"{int((area <= 0).sum())} image(s) show no object pixel")
    return (srgb_to_lab(images) * weight).sum(dim=[2, 3]) / area[:, None]


def colour_spread(lab_means: torch.Tensor) -> float:
    """(K, 3) Lab colours -> sqrt of the summed per-channel variance (population), in Delta E units."""
    check_shape(lab_means, "colour_spread: lab_means", ("K", 3), dtype="float")
    if lab_means.shape[0] < 2:
        raise ValueError("a colour spread needs at least two colours")
    return float(lab_means.float().var(dim=0, unbiased=False).sum().sqrt())


def mean_pairwise_delta_e(images: torch.Tensor, mask: torch.Tensor) -> float:
    """images (K, 3, H, W) in [0, 1] of one shape at one pose (K >= 2), mask (1, H, W) or (K, 1, H, W)
    -> mean over the K(K-1)/2 pairs of the mean per-pixel Delta E on the mask (the union of both
    images' masks when they differ)."""
    sizes = check_shape(images, "mean_pairwise_delta_e: images", ("K", 3, "H", "W"), dtype="float")
    check_shape(mask, "mean_pairwise_delta_e: mask", (1, "H", "W"), (1, 1, "H", "W"), ("K", 1, "H", "W"), sizes=sizes)
    k = images.shape[0]
    if k < 2:
        raise ValueError("pairwise distances need at least two images")
    lab = srgb_to_lab(images)
    masks = mask.float().expand(k, 1, *images.shape[-2:]) if mask.dim() == 3 or mask.shape[0] == 1 else mask.float()
    total, pairs = 0.0, 0
    for i in range(k):
        for j in range(i + 1, k):
            union = torch.maximum(masks[i], masks[j])[0]
            area = float(union.sum())
            if area <= 0:
                continue
            delta = (lab[i] - lab[j]).square().sum(0).sqrt()
            total += float((delta * union).sum()) / area
            pairs += 1
    if pairs == 0:
        raise ValueError("no pair of images shows any object pixel")
    return total / pairs


def gap_closed(untrained: float, trained: float, oracle: float) -> float:
    """Share of the gap between the untrained generator and the oracle that the trained one closes, on
    the log of a distance (lower is better): 0 no better than untrained, 1 as good as the oracle,
    negative worse than untrained. NaN when the oracle is not better than the untrained generator
    (then the distance cannot rank them and the figure would mean nothing)."""
    values = (untrained, trained, oracle)
    if any(not math.isfinite(v) or v <= 0 for v in values) or oracle >= untrained:
        return float("nan")
    return (math.log(untrained) - math.log(trained)) / (math.log(untrained) - math.log(oracle))


def object_set_swd(
    images: torch.Tensor,
    masks: torch.Tensor,
    references: torch.Tensor,
    reference_masks: torch.Tensor,
    patches_per_image: int = 64,
    patch_size: int = 7,
    projections: int = 256,
    min_size: int = 16,
    seed: int = 0,
) -> float:
    """SWD x 1000 between the object patches of a set and of a reference set, pooled over each set.

    images (N, 3, H, W) and references (M, 3, H, W) in [0, 1], same H, W; masks (N, 1, H, W) and
    reference_masks (M, 1, H, W) 0/1. Off its mask each image takes its mean object colour; every
    image is split into a Laplacian pyramid (down to ``min_size``); at each level up to
    ``patches_per_image`` random 7x7 neighbourhoods centred on object pixels are drawn per image,
    pooled per set, cut to the smaller set's count, normalised by the reference's per-channel
    statistics and compared with ``projections`` random directions. The mean over the levels with at
    least 16 patches on both sides; NaN if none has.
    """
    sizes = check_shape(images, "object_set_swd: images", ("N", 3, "H", "W"), dtype="float")
    check_shape(masks, "object_set_swd: masks", ("N", 1, "H", "W"), sizes=sizes)
    check_shape(references, "object_set_swd: references", ("M", 3, "H", "W"), sizes=sizes, dtype="float")
    check_shape(reference_masks, "object_set_swd: reference_masks", ("M", 1, "H", "W"), sizes=sizes)
    generator = torch.Generator().manual_seed(seed)

    def pooled(batch: torch.Tensor, batch_masks: torch.Tensor) -> list[torch.Tensor]:
        per_level: list[list[torch.Tensor]] = []
        for b in range(batch.shape[0]):
            mask = batch_masks[b : b + 1].double()
            levels = laplacian_pyramid(_fill_background(batch[b : b + 1].double(), mask), min_size)
            for i, level in enumerate(levels):
                m = (
                    F.interpolate(mask, size=level.shape[-2:], mode="area")
                    if mask.shape[-2:] != level.shape[-2:]
                    else mask
                )
                k = min(patch_size, *level.shape[-2:]) | 1
                if len(per_level) <= i:
                    per_level.append([])
                per_level[i].append(_object_patches(level, m, patches_per_image, k, generator))
        return [torch.cat(chunks) for chunks in per_level]

    levels_ref, levels_img = pooled(references, reference_masks), pooled(images, masks)
    values = []
    for desc_a, desc_b in zip(levels_ref, levels_img):
        n = min(desc_a.shape[0], desc_b.shape[0])
        if n < 16:
            continue
        desc_a = desc_a[torch.randperm(desc_a.shape[0], generator=generator)[:n]]
        desc_b = desc_b[torch.randperm(desc_b.shape[0], generator=generator)[:n]]
        mean, std = desc_a.mean(0), desc_a.std(0).clamp_min(1e-8)
        values.append(1000.0 * sliced_wasserstein((desc_a - mean) / std, (desc_b - mean) / std, projections, generator))
    return sum(values) / len(values) if values else math.nan
