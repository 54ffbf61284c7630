"""The object's mask of a photo that comes without one: the mask network's estimate (a second look at a
far object's square, :data:`MASK_PASSES`), its edges refined by GrabCut (:func:`mesh2tex.photos.estimate_mask`
is GrabCut alone, for when no network is at hand)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from mesh2tex.checks import check_array_shape
from mesh2tex.photos import grabcut_scale, largest_region
from mesh2tex.render import crop_square, object_box

SURE = 0.9  # network probabilities above this (below 1 - this) are fixed as object (background) for GrabCut
# The mesh's outline as a prior: a band this share of the object's square wide on each side of it is left to GrabCut
# (measured on the outside-world photos of docs/results/transfer.md: 0.02, 0.04 and 0.08 all helped, 0.02 most).
OUTLINE_BAND = 0.02

# The network's passes over a photo (:func:`network_probability`): "flip" averages its prediction with that of
# the photo mirrored left to right; "zoom" predicts again on a square around the object the first pass found,
# filled to the network's side, and averages the two there. Zoom is the default: on objects a quarter of the
# photo's area it lifts the mask as used from 0.86 to 0.87 (chairs) and 0.91 to 0.95 (cars); flip lifts the
# network's own estimate everywhere but not the mask as used, nor the poses (docs/results/transfer.md).
MASK_PASSES = ("flip", "zoom")
DEFAULT_MASK_PASSES = ("zoom",)
ZOOM_MARGIN = 0.1  # the zoom pass's square: the object's box grown by this share of its side on each side
# Zoom only when that square is at most this share of the photo's side: on objects that fill the photo a second
# look at nearly the same square moved the outside-world photos' IoU by -0.02 to +0.01 (docs/results/transfer.md).
ZOOM_BELOW = 0.6


def _square_probability(net, small: torch.Tensor, side: int, flip: bool) -> torch.Tensor:
    """small [1, 3, N, N] in [-1, 1], a square at the network's side -> [side, side] probability, the
    prediction resized; with ``flip`` the mean with its run on the mirrored square."""
    logits = net(torch.cat([small, small.flip(-1)]) if flip else small).float().cpu()
    probability = torch.sigmoid(F.interpolate(logits, size=(side, side), mode="bilinear", align_corners=False))
    if flip:
        probability = 0.5 * (probability[:1] + probability[1:].flip(-1))
    return probability[0, 0]


@torch.no_grad()
def network_probability(
    checkpoint: str | Path,
    rgb: np.ndarray,
    device: torch.device | str = "cpu",
    passes: tuple[str, ...] = DEFAULT_MASK_PASSES,
) -> np.ndarray:
    """(H, W) float32 probability that each pixel shows the object, by the mask network.

    rgb: (H, W, 3) uint8. The photo is padded to a square (edge pixels repeated), resized to the
    network's training side, and the prediction is resized back and unpadded. ``passes``: any of
    :data:`MASK_PASSES` (none: one prediction of the whole photo).
    """
    check_array_shape(rgb, "network_probability: rgb", ("H", "W", 3))
    unknown = sorted(set(passes) - set(MASK_PASSES))
    if unknown:
        raise ValueError(f"network_probability: unknown passes {unknown}; choose from {list(MASK_PASSES)}")
    from mesh2tex.models import load_view_network

    net, cfg = load_view_network(checkpoint, "mask", device)
    h, w = rgb.shape[:2]
    side = max(h, w)
    top, left = (side - h) // 2, (side - w) // 2
    # a copy: the photo may be read-only
    image = torch.from_numpy(np.array(rgb, dtype=np.uint8)).permute(2, 0, 1)[None].float() / 127.5 - 1.0
    image = F.pad(image, (left, side - w - left, top, side - h - top), mode="replicate").to(device)
    size = cfg.data.resolution
    flip = "flip" in passes
    probability = _square_probability(net, F.interpolate(image, size=(size, size), mode="area"), side, flip)
    box = None
    if "zoom" in passes:
        found = (probability >= 0.5).numpy()
        box = object_box(found, ZOOM_MARGIN) if found.sum() >= 16 else None
    # a square the network's side or smaller was already seen at full detail: a second look would add none
    if box is not None and size < box[2] <= ZOOM_BELOW * side:
        z_top, z_left, z_side = box
        zoomed = _square_probability(net, crop_square(image, box, size, repeat_edges=True), z_side, flip)
        # the crop's pixels that lie on the square
        r0, c0 = max(0, z_top), max(0, z_left)
        r1, c1 = min(side, z_top + z_side), min(side, z_left + z_side)
        region = probability[r0:r1, c0:c1]
        probability[r0:r1, c0:c1] = 0.5 * (region + zoomed[r0 - z_top : r1 - z_top, c0 - z_left : c1 - z_left])
    return probability[top : top + h, left : left + w].numpy()


def refine_with_grabcut(rgb: np.ndarray, probability: np.ndarray, iterations: int = 3) -> np.ndarray:
    """(H, W) bool: GrabCut started from the network's probability (sure object above :data:`SURE`,
    sure background below 1 - SURE, probable either way in between), then the largest connected
    region. Falls back to the thresholded probability when GrabCut finds no object. rgb (H, W, 3) uint8."""
    sizes = check_array_shape(rgb, "refine_with_grabcut: rgb", ("H", "W", 3))
    check_array_shape(probability, "refine_with_grabcut: probability", ("H", "W"), sizes=sizes)
    import cv2

    h, w = probability.shape
    scale = grabcut_scale(h, w)
    small_size = (max(1, round(w * scale)), max(1, round(h * scale)))
    small = cv2.resize(rgb, small_size, interpolation=cv2.INTER_AREA) if scale < 1 else rgb
    p = cv2.resize(probability, small_size, interpolation=cv2.INTER_LINEAR) if scale < 1 else probability
    seeds = np.where(p >= 0.5, cv2.GC_PR_FGD, cv2.GC_PR_BGD).astype(np.uint8)
    seeds[p >= SURE] = cv2.GC_FGD
    seeds[p <= 1 - SURE] = cv2.GC_BGD
    threshold = probability >= 0.5
    if not (seeds == cv2.GC_FGD).any() or not (seeds == cv2.GC_BGD).any():
        return largest_region(threshold)
    background, foreground = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    cv2.setRNGSeed(0)
    cv2.grabCut(
        cv2.cvtColor(np.ascontiguousarray(small), cv2.COLOR_RGB2BGR),
        seeds,
        None,
        background,
        foreground,
        iterations,
        cv2.GC_INIT_WITH_MASK,
    )
    estimate = ((seeds == cv2.GC_FGD) | (seeds == cv2.GC_PR_FGD)).astype(np.uint8)
    if scale < 1:
        estimate = cv2.resize(estimate, (w, h), interpolation=cv2.INTER_NEAREST)
    estimate = largest_region(estimate.astype(bool))
    return estimate if estimate.sum() >= 16 else largest_region(threshold)


def refine_with_outline(rgb: np.ndarray, outline: np.ndarray, estimate: np.ndarray, side: int) -> np.ndarray:
    """(H, W) bool: GrabCut started from the mesh's outline at the found pose and the earlier estimate.

    outline (H, W) bool, where the mesh covers the photo at the pose (:func:`mesh2tex.transfer.photo.
    silhouette_in_photo`); estimate (H, W) float in [0, 1], the mask network's probability (or an
    estimated mask as 0/1); side: the object's square in pixels. The outline's prior is 1 well inside
    it, 0 well outside, 0.7 and 0.3 in a band of :data:`OUTLINE_BAND` x ``side`` pixels on either side
    of its edge; GrabCut starts from the mean of that prior and ``estimate`` (:func:`refine_with_grabcut`):
    sure object where both are, sure background where both are. rgb (H, W, 3) uint8."""
    sizes = check_array_shape(rgb, "refine_with_outline: rgb", ("H", "W", 3))
    check_array_shape(outline, "refine_with_outline: outline", ("H", "W"), sizes=sizes)
    check_array_shape(estimate, "refine_with_outline: estimate", ("H", "W"), sizes=sizes)
    import cv2

    band = max(2, int(round(OUTLINE_BAND * side)))
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * band + 1, 2 * band + 1))
    outline = np.asarray(outline, dtype=np.uint8)
    inside, near = cv2.erode(outline, disc).astype(bool), cv2.dilate(outline, disc).astype(bool)
    prior = np.where(outline > 0, 0.7, 0.3).astype(np.float32)
    prior[inside], prior[~near] = 1.0, 0.0
    return refine_with_grabcut(rgb, 0.5 * prior + 0.5 * np.asarray(estimate, dtype=np.float32))
