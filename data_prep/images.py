"""``mesh2tex prepare images``: square crops and masks of the photos the texture GAN learns from.

For every image under ``--input`` (recursive) the object's mask comes from, in order: a mask file of
the same stem under ``--masks``, the image's alpha channel, or an estimate (OpenCV GrabCut seeded
with the image border as background). The image is cropped to a square around the mask (with a
margin), padded with white where the square leaves the photo, and resized to ``--size``. Output:
``DIR/images/<name>.png``, ``DIR/masks/<name>.png`` and ``DIR/index.json`` (per input: status,
reason, mask source, mask coverage). Exit status 0 when every image succeeded, 2 when any failed.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import time
from pathlib import Path

import numpy as np

from mesh2tex.errors import UserError
from mesh2tex.io.atomic import write_json
from mesh2tex.io.images import is_image_file, load_image, load_mask, save_png
from mesh2tex.progress import progress_bar

MARGIN = 0.1  # fraction of the mask's larger side added around it before the square crop


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--input", required=True, metavar="DIR", help="folder of photos (searched recursively)")
    parser.add_argument("--output", required=True, metavar="DIR", help="folder for images/, masks/ and index.json")
    parser.add_argument("--size", type=int, default=256, help="side of the square output images in pixels (default 256)")
    parser.add_argument("--masks", metavar="DIR", default=None, help="folder of mask images named like the photos (any image suffix)")


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
    """Crop a square around the mask's bounding box (plus ``margin``) and resize it.

    Args:
        rgb: (H, W, 3) uint8; mask: (H, W) bool, not empty.
    Returns:
        (size, size, 3) uint8 image (white outside the photo) and (size, size) bool mask.
    """
    import cv2

    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    top, bottom, left, right = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    side = int(np.ceil(max(bottom - top, right - left) * (1 + 2 * margin)))
    center_y, center_x = (top + bottom) / 2.0, (left + right) / 2.0
    y0, x0 = int(round(center_y - side / 2.0)), int(round(center_x - side / 2.0))
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


def find_mask_file(masks_dir: Path | None, relative: Path) -> Path | None:
    """The mask of a photo: same relative path and stem under ``masks_dir``, any image suffix; or None."""
    if masks_dir is None:
        return None
    folder = masks_dir / relative.parent
    for candidate in sorted(folder.glob(f"{relative.stem}.*")) if folder.is_dir() else []:
        if is_image_file(candidate):
            return candidate
    flat = sorted(p for p in masks_dir.glob(f"{relative.stem}.*") if is_image_file(p))
    return flat[0] if flat else None


def prepare_image(path: Path, relative: Path, name: str, output: Path, size: int, masks_dir: Path | None) -> dict:
    """Crop one photo and its mask into ``output``; returns its index record (never raises for bad input)."""
    start = time.perf_counter()
    record = {"source": str(path), "name": name}
    try:
        rgb, alpha = load_image(path)
        mask_file = find_mask_file(masks_dir, relative)
        if mask_file is not None:
            mask = load_mask(mask_file)
            if mask.shape != rgb.shape[:2]:
                raise UserError(f"{mask_file}: mask is {mask.shape[1]}x{mask.shape[0]} but the photo is {rgb.shape[1]}x{rgb.shape[0]}")
            source = f"file {mask_file}"
        elif alpha is not None and alpha.min() < 128:
            mask, source = alpha >= 128, "alpha"
        else:
            mask, source = estimate_mask(rgb), "estimated (GrabCut)"
        if not mask.any():
            raise UserError(f"{path}: the object's mask is empty ({source})")
        image, out_mask = square_crop(rgb, mask, size)
        save_png(output / "images" / f"{name}.png", image)
        save_png(output / "masks" / f"{name}.png", out_mask)
        record.update(status="ok", reason="", mask=source, coverage=round(float(out_mask.mean()), 4))
    except UserError as error:
        record.update(status="failed", reason=str(error))
    except Exception as error:  # unforeseen: reported, the batch goes on
        record.update(status="failed", reason=f"{path}: unexpected {error.__class__.__name__}: {error}")
    record["seconds"] = round(time.perf_counter() - start, 3)
    return record


def run(args) -> int:
    input_dir, output = Path(args.input), Path(args.output)
    if not input_dir.is_dir():
        raise UserError(f"{input_dir}: no such folder")
    if args.size < 8:
        raise UserError(f"--size must be at least 8 (got {args.size})")
    masks_dir = Path(args.masks) if args.masks else None
    if masks_dir is not None and not masks_dir.is_dir():
        raise UserError(f"{masks_dir}: no such mask folder")
    photos = []
    for root, dirs, files in os.walk(input_dir):
        dirs.sort()
        photos.extend(Path(root) / f for f in sorted(files) if is_image_file(f))
    if masks_dir is not None:
        photos = [p for p in photos if masks_dir.resolve() not in p.resolve().parents]
    if not photos:
        raise UserError(f"{input_dir}: no images ({' '.join(s for s in ('.png', '.jpg', '.jpeg', '.bmp', '.tif', '.webp'))})")
    output.mkdir(parents=True, exist_ok=True)
    records, used = [], set()
    for path in progress_bar(photos, desc="prepare images", unit="image"):
        relative = path.relative_to(input_dir)
        name = re.sub(r"[^A-Za-z0-9_.-]", "_", str(relative.with_suffix("")).replace(os.sep, "_"))
        while name in used:
            name += "_"
        used.add(name)
        record = prepare_image(path, relative, name, output, args.size, masks_dir)
        if record["status"] == "failed":
            print(f"mesh2tex: failed: {record['reason']}", file=sys.stderr)
        records.append(record)
    failed = sum(r["status"] == "failed" for r in records)
    write_json(output / "index.json", {"settings": {"size": int(args.size), "masks": str(masks_dir) if masks_dir else None},
                                       "images": records, "ok": len(records) - failed, "failed": failed})
    print(f"prepared {len(records) - failed} of {len(records)} images into {output}" + (f"; failed: {failed}" if failed else ""))
    return 2 if failed else 0
