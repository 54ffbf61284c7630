"""Photos of an object: its mask estimated when none is given, and the square crop around it as arrays.

``mesh2tex prepare images`` writes its crops with :func:`square_crop`; the transfer estimates a
query's mask with :func:`estimate_mask`. Both frame the object as :mod:`mesh2tex.render.crop` does.
"""

from __future__ import annotations

import numpy as np

from mesh2tex.render.crop import object_box

MARGIN = 0.1  # fraction of the mask's larger side added around it before the square crop


def estimate_mask(rgb: np.ndarray, iterations: int = 5) -> np.ndarray:
    """Foreground estimate by GrabCut with a border prior: the outer 4 % of the photo is background.

    Args:
        rgb: (H, W, 3) uint8.
    Returns:
        (H, W) bool, the largest connected foreground region.
    """
    import cv2

    h, w = rgb.shape[:2]
    scale = min(1.0, 320.0 / max(h, w))  # GrabCut is slow on large photos; the mask is upsampled after
    small = cv2.resize(rgb, (max(1, round(w * scale)), max(1, round(h * scale))), interpolation=cv2.INTER_AREA) if scale < 1 else rgb
    sh, sw = small.shape[:2]
    border = max(1, round(0.04 * min(sh, sw)))
    if sh <= 2 * border + 1 or sw <= 2 * border + 1:
        return np.ones((h, w), dtype=bool)
    mask = np.zeros((sh, sw), np.uint8)
    background, foreground = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    rect = (border, border, sw - 2 * border, sh - 2 * border)
    cv2.setRNGSeed(0)
    cv2.grabCut(cv2.cvtColor(small, cv2.COLOR_RGB2BGR), mask, rect, background, foreground, iterations, cv2.GC_INIT_WITH_RECT)
    estimate = ((mask == cv2.GC_FGD) | (mask == cv2.GC_PR_FGD)).astype(np.uint8)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(estimate, connectivity=8)
    if count > 1:
        largest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
        estimate = (labels == largest).astype(np.uint8)
    if scale < 1:
        estimate = cv2.resize(estimate, (w, h), interpolation=cv2.INTER_NEAREST)
    return estimate.astype(bool)


def square_crop(rgb: np.ndarray, mask: np.ndarray, size: int, margin: float = MARGIN) -> tuple[np.ndarray, np.ndarray]:
    """Crop the square around the mask's bounding box (plus ``margin``, :func:`mesh2tex.render.object_box`) and
    resize it with OpenCV (area averaging when shrinking).

    Args:
        rgb: (H, W, 3) uint8; mask: (H, W) bool, not empty.
    Returns:
        (size, size, 3) uint8 image (white outside the photo) and (size, size) bool mask.
    """
    import cv2

    y0, x0, side = object_box(mask, margin)
    h, w = mask.shape
    canvas = np.full((side, side, 3), 255, np.uint8)
    canvas_mask = np.zeros((side, side), np.uint8)
    sy0, sx0, sy1, sx1 = max(0, y0), max(0, x0), min(h, y0 + side), min(w, x0 + side)
    canvas[sy0 - y0:sy1 - y0, sx0 - x0:sx1 - x0] = rgb[sy0:sy1, sx0:sx1]
    canvas_mask[sy0 - y0:sy1 - y0, sx0 - x0:sx1 - x0] = mask[sy0:sy1, sx0:sx1]
    interpolation = cv2.INTER_AREA if side > size else cv2.INTER_LINEAR
    image = cv2.resize(canvas, (size, size), interpolation=interpolation)
    out_mask = cv2.resize(canvas_mask * 255, (size, size), interpolation=interpolation) >= 128
    return image, out_mask
