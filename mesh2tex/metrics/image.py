"""Paired image metrics, for renders whose geometry and pose match the reference exactly.

Images are [B, 3, H, W] float in [0, 1] (use :func:`to_unit` for [-1, 1]); masks [B, 1, H, W] in
{0, 1} (None: every pixel). Each function returns one value per image pair, [B] float64, so callers
can report means and per-pair values alike.
"""

from __future__ import annotations

import kornia
import torch

from mesh2tex.checks import check_shape


def to_unit(images: torch.Tensor) -> torch.Tensor:
    """[-1, 1] network colours -> [0, 1]."""
    return (images + 1.0) * 0.5


def _check_pair(
    function: str, images: torch.Tensor, references: torch.Tensor | None, masks: torch.Tensor | None
) -> None:
    """images [B, 3, H, W] float with masks [B, 1, H, W] or None and references [B, 3, H, W] (None: none to
    check); the message names ``function`` and the argument."""
    sizes = check_shape(images, f"{function}: images", ("B", 3, "H", "W"), dtype="float")
    check_shape(masks, f"{function}: masks", ("B", 1, "H", "W"), sizes=sizes, optional=True)
    if references is not None:
        check_shape(references, f"{function}: references", ("B", 3, "H", "W"), sizes=sizes, dtype="float")


def _weights(images: torch.Tensor, masks: torch.Tensor | None) -> torch.Tensor:
    if masks is None:
        return torch.ones_like(images[:, :1])
    return masks.to(images.dtype)


def masked_psnr(images: torch.Tensor, references: torch.Tensor, masks: torch.Tensor | None = None) -> torch.Tensor:
    """PSNR in dB over the masked pixels (peak 1): 10 log10(1 / MSE). Identical images give +inf;
    an empty mask gives NaN."""
    _check_pair("masked_psnr", images, references, masks)
    weights = _weights(images, masks)
    squared = (images.double() - references.double()).pow(2) * weights
    mse = squared.sum(dim=(1, 2, 3)) / (weights.double().sum(dim=(1, 2, 3)) * images.shape[1])
    return 10.0 * torch.log10(1.0 / mse)


def masked_ssim(
    images: torch.Tensor, references: torch.Tensor, masks: torch.Tensor | None = None, window_size: int = 11
) -> torch.Tensor:
    """SSIM (kornia, Gaussian window ``window_size``, data range 1) averaged over the masked pixels
    and the channels; 1 for identical images."""
    _check_pair("masked_ssim", images, references, masks)
    ssim_map = kornia.metrics.ssim(images.float(), references.float(), window_size, max_val=1.0)  # [B, C, H, W]
    weights = _weights(images, masks).double()
    return (ssim_map.double() * weights).sum(dim=(1, 2, 3)) / (weights.sum(dim=(1, 2, 3)) * images.shape[1])


def colour_histograms(images: torch.Tensor, masks: torch.Tensor | None = None, bins: int = 8) -> torch.Tensor:
    """Joint RGB histograms of the masked pixels, ``bins`` per channel, normalised to sum 1: [B, bins^3].
    images [B, 3, H, W] in [0, 1], masks [B, 1, H, W] or None."""
    _check_pair("colour_histograms", images, None, masks)
    weights = _weights(images, masks)[:, 0].reshape(images.shape[0], -1).double()
    quantised = (images.clamp(0, 1) * bins).long().clamp_max(bins - 1)  # [B, 3, H, W]
    index = (quantised[:, 0] * bins + quantised[:, 1]) * bins + quantised[:, 2]
    histograms = torch.zeros(images.shape[0], bins**3, dtype=torch.float64, device=images.device)
    histograms.scatter_add_(1, index.reshape(images.shape[0], -1), weights)
    return histograms / histograms.sum(dim=1, keepdim=True).clamp_min(1e-12)


def colour_histogram_distance(
    images: torch.Tensor,
    references: torch.Tensor,
    masks: torch.Tensor | None = None,
    reference_masks: torch.Tensor | None = None,
    bins: int = 8,
) -> torch.Tensor:
    """Total-variation distance (half the L1 distance) between joint RGB histograms (``bins`` per channel)
    of the masked pixels: 0 for the same colour distribution, 1 for disjoint colours. The two images may
    have different masks (``reference_masks`` defaults to ``masks``) and even sizes: images [B, 3, H, W] with
    masks [B, 1, H, W] or None, references [B, 3, H', W'] with reference_masks [B, 1, H', W'] or None."""
    sizes = check_shape(images, "colour_histogram_distance: images", ("B", 3, "H", "W"), dtype="float")
    check_shape(masks, "colour_histogram_distance: masks", ("B", 1, "H", "W"), sizes=sizes, optional=True)
    own = "H" if reference_masks is None and masks is not None else "H'"
    check_shape(
        references,
        "colour_histogram_distance: references",
        ("B", 3, own, own.replace("H", "W")),
        sizes=sizes,
        dtype="float",
    )
    check_shape(
        reference_masks, "colour_histogram_distance: reference_masks", ("B", 1, "H'", "W'"), sizes=sizes, optional=True
    )
    reference_masks = masks if reference_masks is None else reference_masks
    difference = colour_histograms(images, masks, bins) - colour_histograms(references, reference_masks, bins)
    return 0.5 * difference.abs().sum(dim=1)
