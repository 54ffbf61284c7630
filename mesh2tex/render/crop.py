"""Square crops around an object: the one framing used by every image the networks see.

A photo, a rendered training view and a render being optimised are all framed the same way: the
square around the object's mask, enlarged by ``margin`` of its larger side on each side, resized to
the working resolution. Keeping one definition here keeps train-time and query-time inputs alike.
"""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F

from mesh2tex.checks import check_shape


def object_box(mask: np.ndarray, margin: float) -> tuple[int, int, int]:
    """(top, left, side) of the square around ``mask`` (H,W bool) with ``margin`` on each side.

    The square may reach outside the image; :func:`crop_square` pads there. Raises ValueError for a
    mask that is not (H,W) or has no object pixel (a caller reading a user's mask checks that first
    and names the file).
    """
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise ValueError(f"object_box: mask must have shape [H, W], got {list(mask.shape)}")
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        raise ValueError("object_box: the object mask is empty")
    top, bottom, left, right = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    side = int(math.ceil(max(bottom - top, right - left) * (1 + 2 * margin)))
    return int(round((top + bottom - side) / 2)), int(round((left + right - side) / 2)), side


def crop_square(
    images: torch.Tensor, box: tuple[int, int, int], size: int, fill: float = 0.0, repeat_edges: bool = False
) -> torch.Tensor:
    """images (N,C,H,W) float -> (N,C,size,size): the square ``box`` (top, left, side) (padded with
    ``fill`` outside, or with the edge pixels repeated for ``repeat_edges``), resized. Differentiable."""
    check_shape(images, "crop_square: images", (None, None, "H", "W"), dtype="float")
    if len(box) != 3:
        raise ValueError(f"crop_square: box must be (top, left, side), got {box!r}")
    top, left, side = box
    h, w = images.shape[-2:]
    pad = (max(0, -left), max(0, left + side - w), max(0, -top), max(0, top + side - h))
    padded = F.pad(images, pad, mode="replicate") if repeat_edges else F.pad(images, pad, value=fill)
    crop = padded[..., top + pad[2] : top + pad[2] + side, left + pad[0] : left + pad[0] + side]
    mode = "area" if side > size else "bilinear"
    return F.interpolate(crop, size=(size, size), mode=mode, **({} if mode == "area" else {"align_corners": False}))


def crop_mask(mask: np.ndarray | torch.Tensor, box: tuple[int, int, int], size: int) -> torch.Tensor:
    """An object mask (H,W) (or (1,H,W), (1,1,H,W)) bool/{0,1}, array or tensor, cut like an image with
    :func:`crop_square`: (1,1,size,size) float {0,1}.

    Resampling blends the mask's edge; a pixel is object where at least half of it was.
    """
    mask = mask.float() if isinstance(mask, torch.Tensor) else torch.from_numpy(np.asarray(mask)).float()
    check_shape(mask, "crop_mask: mask", ("H", "W"), (1, "H", "W"), (1, 1, "H", "W"))
    return (crop_square(mask.reshape(1, 1, *mask.shape[-2:]), box, size) > 0.5).float()
