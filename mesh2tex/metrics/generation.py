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
"""

from __future__ import annotations

import math

import torch
from kornia.color import rgb_to_lab


def srgb_to_lab(images: torch.Tensor) -> torch.Tensor:
    """images (N, 3, H, W) sRGB in [0, 1] -> (N, 3, H, W) CIELAB (L in [0, 100])."""
    if images.dim() != 4 or images.shape[1] != 3:
        raise ValueError(f"images must be (N, 3, H, W), got {tuple(images.shape)}")
    return rgb_to_lab(images.float().clamp(0, 1))


def mean_object_lab(images: torch.Tensor, masks: torch.Tensor) -> torch.Tensor:
    """images (N, 3, H, W) in [0, 1], masks (N, 1, H, W) 0/1 -> (N, 3) mean Lab of the object pixels.

    Raises ValueError when an image has no object pixel.
    """
    if masks.shape[0] != images.shape[0] or masks.shape[-2:] != images.shape[-2:]:
        raise ValueError(f"masks {tuple(masks.shape)} do not match images {tuple(images.shape)}")
    weight = masks.float()
    area = weight.sum(dim=[1, 2, 3])
    if (area <= 0).any():
        raise ValueError(f"{int((area <= 0).sum())} image(s) show no object pixel")
    return (srgb_to_lab(images) * weight).sum(dim=[2, 3]) / area[:, None]


def colour_spread(lab_means: torch.Tensor) -> float:
    """(K, 3) Lab colours -> sqrt of the summed per-channel variance (population), in Delta E units."""
    if lab_means.shape[0] < 2:
        raise ValueError("a colour spread needs at least two colours")
    return float(lab_means.float().var(dim=0, unbiased=False).sum().sqrt())


def mean_pairwise_delta_e(images: torch.Tensor, mask: torch.Tensor) -> float:
    """images (K, 3, H, W) in [0, 1] of one shape at one pose (K >= 2), mask (1, H, W) or (K, 1, H, W)
    -> mean over the K(K-1)/2 pairs of the mean per-pixel Delta E on the mask (the union of both
    images' masks when they differ)."""
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
