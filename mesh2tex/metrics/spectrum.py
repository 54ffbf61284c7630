"""Speckle: how much of a rendered texture's power lies at high spatial frequencies.

A texture that matches a photo set's colours and coarse statistics can still be grainy: pixel-scale
noise that no material of the photos shows. This measure looks at the texture alone, on renders:

1. **Object patches.** Square ``patch`` x ``patch`` windows (stride half a patch) that lie wholly on
   the object (every pixel inside the mask), so that silhouettes and the background add no power.
2. **Power spectrum.** Each patch's CIELAB lightness L* (``space="L"``; or L*, a*, b* summed,
   ``space="lab"``), its Hann-weighted mean removed, times a 2D Hann window, through a 2D FFT:
   ``|F(fx, fy)|^2``, the DC bin left out.
3. **High-frequency share.** The power at radial frequencies ``sqrt(fx^2 + fy^2)`` at or above
   ``cutoff``, over all the power, pooled over every patch of the set (a ratio of sums, so
   low-contrast patches weigh little). 0: only slow changes (or no change at all: a flat colour
   has no power, and scores 0); white noise scores the share of the frequency square beyond the
   cutoff (0.80 at a quarter cycle per pixel).

**Scale.** ``cutoff`` is in cycles per pixel, or, given ``pixels_per_unit`` (one figure per image:
how many pixels one unit of the object's normalised frame, its bounding-box diagonal, spans at the
object's centre; :func:`view_pixels_per_unit` for the orbit camera), in **cycles per object
diagonal**: a physical scale on the object, so that two renders at different distances or texel
densities compare. Every row of a comparison must be rendered the same way (same cameras,
resolution, supersampling and lighting): the render's own filtering shapes the top of the spectrum.

    high_frequency_share   the measure, pooled over a set of renders -> SpeckleResult
    radial_power           the mean power per radial frequency band (for figures and tables)
    object_patches         the patches wholly on the object, with the image each comes from
    view_pixels_per_unit   pixels per unit of the normalised frame for an orbit camera
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
import torch.nn.functional as F

from mesh2tex.checks import check_shape
from mesh2tex.metrics.generation import srgb_to_lab

SPACES = ("L", "lab")
DEFAULT_CUTOFF = 40.0  # cycles per object diagonal (about 3 cm on a chair, 12 cm on a car), with pixels_per_unit
DEFAULT_PATCH = 16  # pixels
_NO_POWER = 1e-12  # power per patch below which a set counts as flat (rounding noise of a constant patch)


@dataclass(frozen=True)
class SpeckleResult:
    """The high-frequency share of a set of renders and what it was pooled from."""

    share: float  # power at or above the cutoff / all power (0 when there is no power at all: a flat colour)
    high_power: float  # mean power per patch at or above the cutoff (L* units squared, summed over bins)
    total_power: float  # mean power per patch without DC
    patches: int  # patches pooled


def view_pixels_per_unit(distance: float, fov: float, resolution: int) -> float:
    """Pixels spanned by one unit of the normalised frame at the object's centre, seen by an orbit camera
    ``distance`` units away with a vertical field of view ``fov`` degrees, on a ``resolution``-pixel
    square image: ``resolution / (2 * distance * tan(fov / 2))``."""
    if distance <= 0 or not 0 < fov < 180 or resolution <= 0:
        raise ValueError(f"need distance > 0, 0 < fov < 180 and resolution > 0, got {distance}, {fov}, {resolution}")
    return resolution / (2.0 * distance * math.tan(math.radians(fov) / 2.0))


def _check_images(function: str, images: torch.Tensor, masks: torch.Tensor, channels: int | str = 3) -> None:
    """images (B, channels, H, W) float and masks (B, 1, H, W), named ``function: images`` and ``function: masks``."""
    sizes = check_shape(images, f"{function}: images", ("B", channels, "H", "W"), dtype="float")
    check_shape(masks, f"{function}: masks", ("B", 1, "H", "W"), sizes=sizes)


def object_patches(
    images: torch.Tensor, masks: torch.Tensor, patch: int = DEFAULT_PATCH, stride: int = 0
) -> tuple[torch.Tensor, torch.Tensor]:
    """Patches wholly on the object.

    Args:
        images: (B, C, H, W) float.
        masks: (B, 1, H, W), object where > 0.5.
        patch: the patch side P in pixels.
        stride: pixels between patch corners (0: P // 2).
    Returns:
        patches (N, C, P, P) and owner (N,) int64, the image index of each patch.
    """
    _check_images("object_patches", images, masks, channels="C")
    if patch < 4 or patch > min(images.shape[-2:]):
        raise ValueError(f"patch must be between 4 and the image side {min(images.shape[-2:])}, got {patch}")
    stride = stride or max(1, patch // 2)
    b, c = images.shape[:2]
    inside = F.avg_pool2d((masks > 0.5).float(), patch, stride) > 1.0 - 1e-6  # (B, 1, h, w): every pixel on the object
    columns = F.unfold(images.float(), patch, stride=stride)  # (B, C*P*P, h*w)
    keep = inside.flatten(1)  # (B, h*w)
    patches = columns.transpose(1, 2)[keep].reshape(-1, c, patch, patch)
    owner = torch.arange(b)[:, None].expand_as(keep)[keep]
    return patches, owner


def _channels(images: torch.Tensor, space: str) -> torch.Tensor:
    """(B, 3, H, W) sRGB in [0, 1] -> (B, C, H, W): L* (C = 1) or L*, a*, b* (C = 3)."""
    if space not in SPACES:
        raise ValueError(f"space must be one of {', '.join(SPACES)}, got {space!r}")
    lab = srgb_to_lab(images)
    return lab[:, :1] if space == "L" else lab


def _patch_power(patches: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """patches (N, C, P, P) -> power (N, P, P) summed over channels (DC bin 0), radius (P, P) in cycles per pixel."""
    p = patches.shape[-1]
    hann = torch.hann_window(p, periodic=False, dtype=torch.float64)
    window = hann[:, None] * hann[None, :]
    x = patches.double()
    mean = (x * window).sum(dim=(-2, -1), keepdim=True) / window.sum()
    spectrum = torch.fft.fft2((x - mean) * window)
    power = spectrum.abs().square().sum(dim=1)  # (N, P, P)
    power[:, 0, 0] = 0.0
    f = torch.fft.fftfreq(p, dtype=torch.float64)
    radius = torch.sqrt(f[:, None] ** 2 + f[None, :] ** 2)
    return power, radius


def _cutoffs(cutoff: float, owner: torch.Tensor, batch: int, pixels_per_unit) -> torch.Tensor:
    """The cutoff in cycles per pixel for each patch (N,)."""
    if pixels_per_unit is None:
        return torch.full((len(owner),), float(cutoff), dtype=torch.float64)
    ppu = torch.as_tensor(pixels_per_unit, dtype=torch.float64).reshape(-1)
    if ppu.numel() == 1:
        ppu = ppu.expand(batch)
    if ppu.numel() != batch or (ppu <= 0).any():
        raise ValueError(f"pixels_per_unit must be positive, one per image ({batch}), got {tuple(ppu.shape)}")
    return cutoff / ppu[owner]


def high_frequency_share(
    images: torch.Tensor,
    masks: torch.Tensor,
    cutoff: float = DEFAULT_CUTOFF,
    *,
    pixels_per_unit=None,
    patch: int = DEFAULT_PATCH,
    space: str = "L",
) -> SpeckleResult:
    """The share of the object's texture power at or above ``cutoff``, pooled over a set of renders.

    Args:
        images: (B, 3, H, W) sRGB in [0, 1] (renders; the background does not matter).
        masks: (B, 1, H, W), object where > 0.5.
        cutoff: cycles per pixel (< 0.71), or cycles per unit of the normalised frame with ``pixels_per_unit``.
        pixels_per_unit: None, a float, or (B,) floats: pixels per unit of the object's normalised frame
            in each image (:func:`view_pixels_per_unit`).
        patch: patch side in pixels (a power of two is not needed).
        space: "L" (CIELAB lightness) or "lab" (L*, a*, b* power summed).
    Returns:
        :class:`SpeckleResult`; ``patches`` 0 (and share 0) when no patch fits on any object.
    """
    _check_images("high_frequency_share", images, masks)
    patches, owner = object_patches(_channels(images, space), masks, patch)
    if len(patches) == 0:
        return SpeckleResult(0.0, 0.0, 0.0, 0)
    power, radius = _patch_power(patches)
    high = radius[None] >= _cutoffs(cutoff, owner, images.shape[0], pixels_per_unit)[:, None, None]
    total = float(power.sum())
    high_power = float((power * high).sum())
    n = len(patches)
    return SpeckleResult(
        share=high_power / total if total > _NO_POWER * n else 0.0,
        high_power=high_power / n,
        total_power=total / n,
        patches=n,
    )


def radial_power(
    images: torch.Tensor,
    masks: torch.Tensor,
    edges,
    *,
    pixels_per_unit=None,
    patch: int = DEFAULT_PATCH,
    space: str = "L",
) -> torch.Tensor:
    """The share of the power in each radial frequency band, pooled over the object patches of a set.

    ``edges`` (K + 1,) increasing band edges, in cycles per pixel, or in cycles per unit with
    ``pixels_per_unit`` (as :func:`high_frequency_share`). -> (K,) float64: band power / all power
    (the power outside the edges counts in the total; zeros when there is no power). images (B, 3, H, W) sRGB
    in [0, 1], masks (B, 1, H, W).
    """
    _check_images("radial_power", images, masks)
    patches, owner = object_patches(_channels(images, space), masks, patch)
    edges = torch.as_tensor(edges, dtype=torch.float64)
    if len(patches) == 0:
        return torch.zeros(len(edges) - 1, dtype=torch.float64)
    power, radius = _patch_power(patches)
    scale = _cutoffs(1.0, owner, images.shape[0], pixels_per_unit)  # cycles per pixel of one cycle per unit
    frequency = radius[None] / scale[:, None, None]  # (N, P, P) in the edges' units
    total = power.sum()
    out = torch.zeros(len(edges) - 1, dtype=torch.float64)
    for k in range(len(edges) - 1):
        band = (frequency >= edges[k]) & (frequency < edges[k + 1])
        out[k] = (power * band).sum()
    return out / total if total > 0 else out


__all__ = [
    "DEFAULT_CUTOFF",
    "DEFAULT_PATCH",
    "SPACES",
    "SpeckleResult",
    "high_frequency_share",
    "object_patches",
    "radial_power",
    "view_pixels_per_unit",
]
