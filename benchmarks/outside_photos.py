"""The backdrops of ``outside_transfer.py``'s photos: a drawn room, a crop of a photograph, and the object seen
from farther in a room; drawn here, not by the training code's backdrops (:mod:`mesh2tex.synthetic.backdrops`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

# Photographs the world and the mask network's training never show (mesh2tex.synthetic.backdrops uses others).
BACKDROPS = ("astronaut", "chelsea", "camera", "coins", "clock", "page")


def backdrop(index: int, size: int, rng: np.random.Generator) -> np.ndarray:
    """(size, size, 3) float32 in [0, 1]: a sharp crop of one of scikit-image's photographs."""
    import cv2

    from mesh2tex.synthetic.world import background_photo

    image = background_photo(BACKDROPS[index % len(BACKDROPS)])
    h, w = image.shape[:2]
    side = int(min(h, w) * rng.uniform(0.5, 0.9))
    y, x = int(rng.integers(0, h - side + 1)), int(rng.integers(0, w - side + 1))
    crop = cv2.resize(
        np.ascontiguousarray(image[y : y + side, x : x + side]), (size, size), interpolation=cv2.INTER_AREA
    )
    return crop.astype(np.float32) / 255.0


def write_jpeg(path: Path, rgb: np.ndarray) -> None:
    """rgb (H, W, 3) float in [0, 1] as a JPEG of quality 90."""
    import cv2

    cv2.imwrite(
        str(path), cv2.cvtColor((rgb * 255).round().astype(np.uint8), cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 90]
    )


def far_photo(rgb: np.ndarray, coverage: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The object at its rendered size at a random place in a room (:func:`room`) twice the photo's side: a
    chair seen from farther, a quarter of the photo's area. rgb (S, S, 3) float, coverage (S, S, 1) in
    [0, 1] -> (the photo (2S, 2S, 3) float, its true mask (2S, 2S) bool)."""
    size = rgb.shape[0]
    canvas = room(2 * size, rng)
    top, left = (int(v) for v in rng.integers(0, size + 1, 2))
    window = canvas[top : top + size, left : left + size]
    canvas[top : top + size, left : left + size] = rgb * coverage + window * (1 - coverage)
    truth = np.zeros((2 * size, 2 * size), dtype=bool)
    truth[top : top + size, left : left + size] = coverage[..., 0] > 0.5
    return canvas, truth


def room(size: int, rng: np.random.Generator) -> np.ndarray:
    """(size, size, 3) float32 in [0, 1]: a wall (a muted colour, lit from above) over a floor of planks
    (each its own shade, with grain), the horizon at 45-75 % of the height; drawn here, not by the
    training code's backdrops."""
    import colorsys

    rows = np.arange(size, dtype=np.float32)[:, None, None]
    horizon = int(size * rng.uniform(0.45, 0.75))
    wall = np.array(
        colorsys.hsv_to_rgb(rng.uniform(0, 1), rng.uniform(0.05, 0.35), rng.uniform(0.55, 0.95)), np.float32
    )
    image = np.broadcast_to(wall * (0.85 + 0.15 * (1 - rows / size)), (size, size, 3)).copy()
    wood = np.array(
        colorsys.hsv_to_rgb(rng.uniform(0.05, 0.11), rng.uniform(0.3, 0.7), rng.uniform(0.25, 0.7)), np.float32
    )
    plank = max(3, int(size * rng.uniform(0.03, 0.08)))
    for top in range(horizon, size, plank):
        shade = float(rng.uniform(0.8, 1.15))
        grain = 1 + 0.06 * np.sin(np.arange(size) * rng.uniform(0.2, 0.6) + rng.uniform(0, 6))[None, :, None]
        image[top : top + plank] = np.clip(wood * shade * grain, 0, 1)
        image[top : top + 1] *= 0.7  # the gap between planks
    image[horizon - 2 : horizon] *= 0.6  # the skirting's shadow
    return np.clip(image, 0.0, 1.0)
