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

from mesh2tex.errors import UserError


def object_box(mask: np.ndarray, margin: float) -> tuple[int, int, int]:
    """(top, left, side) of the square around ``mask`` (H,W bool) with ``margin`` on each side.

    The square may reach outside the image; :func:`crop_square` pads there.
    """
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        raise UserError("the object mask is empty")
    top, bottom, left, right = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    side = int(math.ceil(max(bottom - top, right - left) * (1 + 2 * margin)))
    return int(round((top + bottom - side) / 2)), int(round((left + right - side) / 2)), side


def crop_square(images: torch.Tensor, box: tuple[int, int, int], size: int, fill: float = 0.0) -> torch.Tensor:
    """images (N,C,H,W) -> (N,C,size,size): the square ``box`` (padded with ``fill`` outside), resized. Differentiable."""
    top, left, side = box
    h, w = images.shape[-2:]
    pad = (max(0, -left), max(0, left + side - w), max(0, -top), max(0, top + side - h))
    padded = F.pad(images, pad, value=fill)
    crop = padded[..., top + pad[2] : top + pad[2] + side, left + pad[0] : left + pad[0] + side]
    mode = "area" if side > size else "bilinear"
    return F.interpolate(crop, size=(size, size), mode=mode, **({} if mode == "area" else {"align_corners": False}))


def crop_mask(mask: np.ndarray | torch.Tensor, box: tuple[int, int, int], size: int) -> torch.Tensor:
    """An object mask (H,W) bool/{0,1} cut like an image with :func:`crop_square`: (1,1,size,size) float {0,1}.

    Resampling blends the mask's edge; a pixel is object where at least half of it was.
    """
    mask = mask.float() if isinstance(mask, torch.Tensor) else torch.from_numpy(np.asarray(mask)).float()
    return (crop_square(mask.reshape(1, 1, *mask.shape[-2:]), box, size) > 0.5).float()
