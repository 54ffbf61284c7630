"""Folders of images as tensors for the metrics: listing by file stem, sets resized to one square
side, pairs matched by name, with their masks (a mask file of the same stem, or the alpha channel).

Files are read by :func:`mesh2tex.io.images.load_image` / :func:`mesh2tex.io.images.load_mask`
(uint8 and bool arrays); here they become float tensors in [0, 1].
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from mesh2tex.errors import InputError
from mesh2tex.io.images import IMAGE_SUFFIXES, is_image_file, load_image, load_mask
from mesh2tex.render.shading import composite_images


def image_tensor(path: str | Path) -> tuple[torch.Tensor, torch.Tensor | None]:
    """RGB [3, H, W] float in [0, 1] and alpha [1, H, W] (None without an alpha channel); InputError if not an image."""
    rgb, alpha = load_image(path)
    rgb = torch.from_numpy(np.array(rgb)).permute(2, 0, 1).contiguous().float() / 255.0
    return rgb, (None if alpha is None else torch.from_numpy(np.array(alpha))[None].float() / 255.0)


def mask_tensor(path: str | Path) -> torch.Tensor:
    """A mask file -> [1, H, W] float in {0, 1} (:func:`mesh2tex.io.images.load_mask`)."""
    return torch.from_numpy(load_mask(path))[None].float()


def list_images(folder: str | Path, what: str) -> dict[str, Path]:
    """{file stem: path} of the image files in ``folder`` (sorted); InputError if missing, empty or ambiguous."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: {what} folder not found")
    found: dict[str, Path] = {}
    for path in sorted(folder.iterdir()):
        if is_image_file(path) and path.is_file():
            if path.stem in found:
                raise InputError(f"{folder}: two {what} files share the name '{path.stem}' ({found[path.stem].name}, {path.name})")
            found[path.stem] = path
    if not found:
        raise InputError(f"{folder}: no {what} images ({', '.join(IMAGE_SUFFIXES)})")
    return found


def square_resize(image: torch.Tensor, resolution: int) -> torch.Tensor:
    """Centre-crop [C, H, W] to a square and resize it (antialiased bilinear) to resolution^2."""
    height, width = image.shape[-2:]
    side = min(height, width)
    top, left = (height - side) // 2, (width - side) // 2
    crop = image[:, top:top + side, left:left + side]
    if side == resolution:
        return crop
    return F.interpolate(crop[None], size=(resolution, resolution), mode="bilinear", align_corners=False, antialias=True)[0]


def load_set(folder: str | Path, what: str, resolution: int, background: float,
             masks: dict[str, Path] | None = None) -> tuple[torch.Tensor, torch.Tensor | None]:
    """All images of ``folder`` as [N, 3, R, R] in [0, 1], masked-out pixels set to ``background``, and
    their object masks [N, 1, R, R] (0/1) when every image has one (a ``masks`` file or an alpha
    channel), else None. Every file is checked first (:func:`mesh2tex.photos.read_set_photo`); any
    rejected one is an InputError counting them, each named (:func:`mesh2tex.photos.refuse_rejected`)."""
    from mesh2tex.photos import read_photo_set, read_set_photo, refuse_rejected

    def read(path: Path, mask_path: Path | None) -> tuple[torch.Tensor, torch.Tensor | None]:
        rgb, coverage = read_set_photo(path, mask_path)
        image = torch.from_numpy(np.array(rgb)).permute(2, 0, 1).contiguous().float() / 255.0
        if coverage is None:
            return square_resize(image, resolution), None
        mask = torch.from_numpy(coverage >= 128)[None].float()
        return square_resize(composite_images(image, mask, background), resolution), (square_resize(mask, resolution) > 0.5).float()

    listed = list_images(folder, what)
    items = [(path, masks.get(stem) if masks is not None else None) for stem, path in listed.items()]
    read_set, rejected = read_photo_set(items, read)
    refuse_rejected(rejected, len(items), folder, f"{what}s")
    images = [image for image, _ in read_set]
    object_masks = [mask for _, mask in read_set if mask is not None]
    return torch.stack(images), (torch.stack(object_masks) if len(object_masks) == len(images) else None)


def load_pairs(renders_dir: str | Path, images_dir: str | Path, masks: dict[str, Path] | None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None, list[str]]:
    """Renders and images matched by file stem, with masks; InputError for unmatched names or size mismatches."""
    renders = list_images(renders_dir, "render")
    images = list_images(images_dir, "image")
    missing = sorted(set(renders) - set(images))
    if missing:
        raise InputError(f"{images_dir}: no image for render(s) {', '.join(missing[:5])}{' ...' if len(missing) > 5 else ''} (pairs match by file name)")
    names = sorted(renders)
    render_list, image_list, mask_list = [], [], []
    any_mask = False
    for name in names:
        render, render_alpha = image_tensor(renders[name])
        image, image_alpha = image_tensor(images[name])
        if render.shape != image.shape:
            raise InputError(f"{images[name]}: size {tuple(image.shape[-2:])} differs from its render's {tuple(render.shape[-2:])}")
        if masks is not None and name in masks:
            mask = mask_tensor(masks[name])
        elif render_alpha is not None or image_alpha is not None:
            alphas = [(a > 0.5).float() for a in (render_alpha, image_alpha) if a is not None]
            mask = alphas[0] if len(alphas) == 1 else alphas[0] * alphas[1]
        else:
            mask = None
        if mask is not None and mask.shape[-2:] != render.shape[-2:]:
            raise InputError(f"{masks[name] if masks is not None and name in masks else images[name]}: mask size {tuple(mask.shape[-2:])} "
                            f"differs from the render's {tuple(render.shape[-2:])}")
        any_mask = any_mask or mask is not None
        render_list.append(render)
        image_list.append(image)
        mask_list.append(mask if mask is not None else torch.ones_like(render[:1]))
    if len({tuple(r.shape) for r in render_list}) > 1:
        raise InputError(f"{renders_dir}: renders of different sizes; paired metrics need one size")
    return torch.stack(render_list), torch.stack(image_list), torch.stack(mask_list) if any_mask else None, names
