"""Backdrops for photos of an object: what the mask network learns to tell the object from.

A user's photo shows the object in front of a wall, a floor, furniture, clutter; the world's own
photos have plain, gradient, noise or blurred-photo backgrounds (:func:`mesh2tex.synthetic.world.random_background`).
:func:`backdrop` draws sharper and busier ones: crops of the world's background photographs at
full sharpness, and drawn clutter (rectangles, discs, lines, stripes over a wall colour).
:func:`place_over_backdrops` puts framed renders of an object at a random size and position over
them, the training input of the mask network (:mod:`mesh2tex.nn.mask`).

Only the world's background photographs (``BACKGROUND_PHOTOS``) are used here; benchmarks judge
the mask on photographs this module never shows (``benchmarks/outside_transfer.py``).
"""

from __future__ import annotations

import colorsys
from functools import lru_cache

import numpy as np
import torch
import torch.nn.functional as F

from mesh2tex.synthetic.world import BACKGROUND_PHOTOS, background_photo, random_background

BACKDROP_KINDS = ("photo", "clutter", "noise", "gradient", "solid")
BACKDROP_SHARES = (0.45, 0.3, 0.1, 0.1, 0.05)
SCALE_RANGE = (0.3, 1.0)  # the framed object's side over the photo's side


@lru_cache(maxsize=None)
def _photo(name: str) -> np.ndarray:
    return background_photo(name)


def _colour(rng: np.random.Generator, saturation: float = 0.7) -> np.ndarray:
    return np.array(
        colorsys.hsv_to_rgb(rng.uniform(0, 1), rng.uniform(0.0, saturation), rng.uniform(0.1, 1.0)), dtype=np.float32
    )


def _clutter(rng: np.random.Generator, size: int) -> np.ndarray:
    import cv2

    image = np.ascontiguousarray(
        random_background(str(rng.choice(["solid", "gradient"])), int(rng.integers(1 << 31)), size)
    )
    for _ in range(int(rng.integers(4, 30))):
        colour = tuple(float(c) for c in _colour(rng))
        kind = int(rng.integers(4))
        a = tuple(int(v) for v in rng.integers(-size // 4, size + size // 4, 2))
        b = tuple(int(v) for v in rng.integers(-size // 4, size + size // 4, 2))
        if kind == 0:
            cv2.rectangle(image, a, b, colour, -1)
        elif kind == 1:
            cv2.circle(image, a, int(rng.integers(2, size // 3)), colour, -1)
        elif kind == 2:
            cv2.line(image, a, b, colour, int(rng.integers(1, max(2, size // 24))))
        else:  # stripes: floorboards, blinds, tiles
            period = int(rng.integers(4, max(5, size // 6)))
            band = np.arange(size)[:, None] % period < period // 2
            image = np.where((band if rng.random() < 0.5 else band.T)[..., None], np.asarray(colour, np.float32), image)
    if rng.random() < 0.5:
        image = cv2.GaussianBlur(image, (0, 0), float(rng.uniform(0.3, 2.0)))
    return image


def backdrop(rng: np.random.Generator, size: int) -> np.ndarray:
    """A (size, size, 3) float32 backdrop in [0, 1] of a kind drawn with :data:`BACKDROP_SHARES`."""
    import cv2

    kind = BACKDROP_KINDS[int(rng.choice(len(BACKDROP_KINDS), p=BACKDROP_SHARES))]
    if kind == "clutter":
        return _clutter(rng, size)
    if kind != "photo":
        return np.ascontiguousarray(random_background(kind, int(rng.integers(1 << 31)), size))
    source = _photo(BACKGROUND_PHOTOS[int(rng.integers(len(BACKGROUND_PHOTOS)))])
    h, w = source.shape[:2]
    side = max(8, int(rng.uniform(0.25, 1.0) * min(h, w)))
    top, left = int(rng.integers(0, h - side + 1)), int(rng.integers(0, w - side + 1))
    crop = cv2.resize(
        np.ascontiguousarray(source[top : top + side, left : left + side]), (size, size), interpolation=cv2.INTER_AREA
    )
    crop = crop.astype(np.float32) / 255.0
    if rng.random() < 0.5:
        crop = crop[:, ::-1]
    gain = rng.uniform(0.7, 1.3, size=3).astype(np.float32)  # another wall colour, another light
    return np.ascontiguousarray(np.clip(crop * gain, 0.0, 1.0))


def place_over_backdrops(
    images: torch.Tensor, masks: torch.Tensor, rng: np.random.Generator
) -> tuple[torch.Tensor, torch.Tensor]:
    """Framed views of objects, each shrunk to a random share of the frame (:data:`SCALE_RANGE`), put at
    a random place over a fresh :func:`backdrop`, with a random exposure and a little sensor noise.

    images [B, 3, R, R] in [-1, 1]; masks [B, 1, R, R] in {0, 1}. Returns the new images (same shape
    and range) and their masks (coverage >= 1/2 of the shrunk object).
    """
    batch, _, size, _ = images.shape
    out_images, out_masks = torch.empty_like(images), torch.empty_like(masks)
    for b in range(batch):
        side = max(8, int(round(size * rng.uniform(*SCALE_RANGE))))
        top, left = int(rng.integers(0, size - side + 1)), int(rng.integers(0, size - side + 1))
        rgb = F.interpolate((images[b : b + 1] + 1) / 2, size=(side, side), mode="area")
        cover = F.interpolate(masks[b : b + 1].float(), size=(side, side), mode="area")
        canvas = torch.from_numpy(backdrop(rng, size)).permute(2, 0, 1)[None].to(images)
        alpha = torch.zeros_like(canvas[:, :1])
        alpha[..., top : top + side, left : left + side] = cover
        placed = torch.zeros_like(canvas)
        placed[..., top : top + side, left : left + side] = rgb
        photo = placed * alpha + canvas * (1 - alpha)
        photo = photo * float(rng.uniform(0.8, 1.2)) + float(rng.uniform(-0.05, 0.05))
        photo = photo + float(rng.uniform(0.0, 0.03)) * torch.from_numpy(
            rng.standard_normal(photo.shape).astype(np.float32)
        )
        out_images[b] = photo.clamp(0, 1)[0] * 2 - 1
        out_masks[b] = (alpha[0] >= 0.5).to(masks.dtype)
    return out_images, out_masks
