"""Reading photos of any common kind into RGB uint8 arrays, writing PNGs atomically, and the
conversions of colours at this file boundary (networks work in [-1, 1], files hold uint8)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from mesh2tex.errors import InputError
from mesh2tex.io.atomic import atomic_path

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".gif")


def is_image_file(path: str | os.PathLike) -> bool:
    """True when ``path`` has a suffix :func:`load_image` reads (case-insensitive)."""
    return Path(path).suffix.lower() in IMAGE_SUFFIXES


def _to_uint8(array: np.ndarray) -> np.ndarray:
    """Scale any integer or float image to uint8 (16-bit by its range, floats assumed in [0, 1])."""
    if array.dtype == np.uint8:
        return array
    if array.dtype == np.bool_:
        return array.astype(np.uint8) * 255
    if np.issubdtype(array.dtype, np.integer):
        top = 65535.0 if array.max(initial=0) > 255 else 255.0
        return np.clip(np.round(array.astype(np.float64) / top * 255.0), 0, 255).astype(np.uint8)
    return np.clip(np.round(np.nan_to_num(array.astype(np.float64)) * 255.0), 0, 255).astype(np.uint8)


def read_image(path: str | os.PathLike, convert: Callable):
    """``convert(image)`` of the PIL image in ``path``, decoded in full; every failure to read it
    (missing, empty, not an image, truncated, corrupt, a decompression bomb) is an InputError naming the file."""
    from PIL import Image, UnidentifiedImageError

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: image not found")
    if path.stat().st_size == 0:
        raise InputError(f"{path}: empty file")
    try:
        with Image.open(path) as image:
            image.load()
            return convert(image)
    except InputError:
        raise
    except UnidentifiedImageError:
        raise InputError(f"{path}: not a readable image (not an image, or an unsupported format)") from None
    except Image.DecompressionBombError:
        raise InputError(
            f"{path}: image too large (over {Image.MAX_IMAGE_PIXELS * 2} pixels: a decompression bomb?)"
        ) from None
    except (OSError, ValueError, SyntaxError) as error:
        raise InputError(f"{path}: corrupt image ({error})") from None
    except (
        Exception
    ) as error:  # a damaged file can make a PIL decoder fail in many ways (struct.error, IndexError, ...)
        raise InputError(f"{path}: corrupt image ({error.__class__.__name__}: {error})") from None


def _to_array(image) -> np.ndarray:
    """A loaded PIL image -> (H, W, 3 or 4) array (uint8, or 16-bit / float for the high-depth modes)."""
    from PIL import ImageOps

    image = ImageOps.exif_transpose(image)
    mode = image.mode
    if mode == "P":
        image = image.convert("RGBA" if "transparency" in image.info else "RGB")
    elif mode in ("I;16", "I;16B", "I;16L", "I", "F"):
        array = np.asarray(image)
        if mode.startswith("I;16"):  # 16 bits whatever the largest value (a dark image is not an 8-bit one)
            array = np.round(array.astype(np.float64) / 65535.0 * 255.0).astype(np.uint8)
        return np.repeat(_to_uint8(array)[..., None], 3, axis=2)
    elif mode == "LA" or mode == "PA":
        image = image.convert("RGBA")
    elif mode not in ("RGB", "RGBA"):
        image = image.convert("RGB")
    return np.asarray(image)


def load_image(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray | None]:
    """Read an image as RGB.

    Grayscale, 16-bit, palette, CMYK and RGBA/LA inputs are normalised; EXIF orientation is applied.

    Returns:
        rgb: (H, W, 3) uint8; alpha: (H, W) uint8, or None when the file has no alpha channel
        (a palette with a transparent entry counts as alpha).
    Raises:
        InputError: missing, empty, corrupt or not an image (:func:`read_image`).
    """
    path = Path(path)
    array = read_image(path, _to_array)
    if array.ndim != 3 or array.shape[0] == 0 or array.shape[1] == 0:
        raise InputError(f"{path}: image has no pixels")
    array = _to_uint8(array)
    if array.shape[2] == 4:
        return np.ascontiguousarray(array[..., :3]), np.ascontiguousarray(array[..., 3])
    return np.ascontiguousarray(array[..., :3]), None


def load_mask(path: str | os.PathLike) -> np.ndarray:
    """Read a mask image as (H, W) bool: alpha where present, otherwise gray level above half."""
    rgb, alpha = load_image(path)
    if alpha is not None and alpha.min() < 255:
        return alpha >= 128
    return rgb.mean(axis=2) >= 128


def save_png(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write (H, W), (H, W, 3) or (H, W, 4) uint8 (bool is saved as 0/255) to a PNG atomically."""
    from PIL import Image

    image = np.asarray(image)
    if image.dtype == np.bool_:
        image = image.astype(np.uint8) * 255
    if image.dtype != np.uint8:
        raise ValueError(f"save_png expects uint8 or bool, got {image.dtype}")
    with atomic_path(path, suffix=".png") as tmp:
        Image.fromarray(image).save(tmp, format="PNG")


def colours_to_uint8(colours: torch.Tensor, signed: bool = True) -> np.ndarray:
    """Float colours in [-1, 1] (``signed``) or [0, 1] -> uint8 of the same shape (clamped, rounded half to even)."""
    colours = colours.detach().float()
    scaled = (colours.clamp(-1, 1) + 1) * 127.5 if signed else colours.clamp(0, 1) * 255
    return scaled.round().to(torch.uint8).cpu().numpy()


def images_to_uint8(images: torch.Tensor, signed: bool = True) -> np.ndarray:
    """Images [..., 3, H, W] float in [-1, 1] (``signed``) or [0, 1] -> uint8 [..., H, W, 3] (channels last)."""
    return colours_to_uint8(images.movedim(-3, -1), signed)
