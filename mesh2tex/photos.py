"""Photos of an object: its mask estimated when none is given, the square crop around it as arrays,
and the check of a photo set's files before training or evaluation reads them.

``mesh2tex prepare images`` writes its crops with :func:`square_crop`; the transfer estimates a
query's mask with :func:`estimate_mask`. Both frame the object as :mod:`mesh2tex.render.crop` does.

A photo set (``train gan --images``, ``evaluate --images/--renders``) is read once through
:func:`read_photo_set`, which checks every file (:func:`read_set_photo`: readable, a photo's kind
of image, at least :data:`mesh2tex.limits.MIN_SET_PHOTO_SIDE` pixels a side, a mask of its size
that is a mask and holds the object) and collects one line per rejected file instead of stopping at
the first; :func:`refuse_rejected` prints them and stops the command with one error line. Every set is
listed the same way (:func:`list_images`: the suffixes of :data:`mesh2tex.io.images.IMAGE_SUFFIXES`)
and framed the same way (:func:`square_resize`: centre-cropped to a square, never stretched, then
resized): the GAN's photo collection (:func:`load_photo_collection`) and the metrics' sets
(:func:`load_set`) alike.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from mesh2tex.errors import InputError, one_line, warning
from mesh2tex.io.images import IMAGE_SUFFIXES, is_image_file, load_image, load_mask
from mesh2tex.limits import MIN_SET_PHOTO_SIDE
from mesh2tex.render.crop import crop_mask, crop_square, object_box
from mesh2tex.render.shading import composite_images

# PIL modes of files that hold no photo, though PIL reads them: what the file probably is instead
NOT_PHOTO_MODES = {
    "1": "a 1-bit black-and-white image (a mask?)",
    "I": "a 32-bit integer image (depth or labels?)",
    "F": "a 32-bit float image (depth or data?)",
}

MARGIN = 0.1  # fraction of the mask's larger side added around it before the square crop


GRABCUT_SIDE = 320.0  # GrabCut is slow on large photos: it runs on a copy at most this many pixels a side


def grabcut_scale(height: int, width: int) -> float:
    """The factor (<= 1) a photo of ``height`` x ``width`` is shrunk by before GrabCut; its mask is upsampled after."""
    return min(1.0, GRABCUT_SIDE / max(height, width))


def largest_region(mask: np.ndarray) -> np.ndarray:
    """(H, W) bool: the largest 8-connected region of ``mask`` (the mask itself when it has at most one)."""
    import cv2

    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    if count <= 2:
        return mask.astype(bool)
    return labels == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))


def estimate_mask(rgb: np.ndarray, iterations: int = 5) -> np.ndarray:
    """Foreground estimate by GrabCut with a border prior: the outer 4 % of the photo is background.

    Args:
        rgb: (H, W, 3) uint8.
    Returns:
        (H, W) bool, the largest connected foreground region.
    """
    import cv2

    h, w = rgb.shape[:2]
    scale = grabcut_scale(h, w)
    small = (
        cv2.resize(rgb, (max(1, round(w * scale)), max(1, round(h * scale))), interpolation=cv2.INTER_AREA)
        if scale < 1
        else rgb
    )
    sh, sw = small.shape[:2]
    border = max(1, round(0.04 * min(sh, sw)))
    if sh <= 2 * border + 1 or sw <= 2 * border + 1:
        return np.ones((h, w), dtype=bool)
    mask = np.zeros((sh, sw), np.uint8)
    background, foreground = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    rect = (border, border, sw - 2 * border, sh - 2 * border)
    cv2.setRNGSeed(0)
    cv2.grabCut(
        cv2.cvtColor(small, cv2.COLOR_RGB2BGR), mask, rect, background, foreground, iterations, cv2.GC_INIT_WITH_RECT
    )
    estimate = largest_region((mask == cv2.GC_FGD) | (mask == cv2.GC_PR_FGD)).astype(np.uint8)
    if scale < 1:
        estimate = cv2.resize(estimate, (w, h), interpolation=cv2.INTER_NEAREST)
    return estimate.astype(bool)


def square_crop(rgb: np.ndarray, mask: np.ndarray, size: int, margin: float = MARGIN) -> tuple[np.ndarray, np.ndarray]:
    """The square around the mask's bounding box (plus ``margin``), cut and resized as every image the
    networks see is (:func:`mesh2tex.render.crop.crop_square`, white outside the photo).

    Args:
        rgb: (H, W, 3) uint8; mask: (H, W) bool, not empty.
    Returns:
        (size, size, 3) uint8 image and (size, size) bool mask.
    """
    box = object_box(mask, margin)
    image = crop_square(
        torch.from_numpy(np.ascontiguousarray(rgb)).permute(2, 0, 1)[None].float() / 255.0, box, size, fill=1.0
    )
    image = (image[0].permute(1, 2, 0).clamp(0, 1) * 255.0).round().to(torch.uint8).numpy()
    return image, crop_mask(mask, box, size)[0, 0].numpy() > 0.5


def _mode(path: Path) -> str:
    """The PIL mode of an image file that :func:`mesh2tex.io.images.load_image` has read, from its
    header alone (the pixels are not decoded again)."""
    from PIL import Image

    with Image.open(path) as image:
        return image.mode


def _mask_from_file(path: Path) -> np.ndarray:
    """A mask file as (H, W) uint8 coverage: its alpha where it has transparency, else its gray level;
    InputError for a file that is a photo, not a mask (colours: the folders swapped?)."""
    rgb, alpha = load_image(path)
    if alpha is not None and alpha.min() < 255:
        return alpha
    spread = rgb.max(axis=2).astype(np.int16) - rgb.min(axis=2)
    if float((spread > 32).mean()) > 0.01:  # gray masks have equal channels; a few coloured edge pixels are forgiven
        raise InputError(
            f"{path}: not a mask: {float((spread > 32).mean()):.0%} of its pixels are coloured (expected white object "
            "on black)"
        )
    return np.round(rgb.mean(axis=2)).astype(np.uint8)


def read_set_photo(path: str | Path, mask_path: str | Path | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """One photo of a set, checked: rgb (H, W, 3) uint8 and its object's coverage (H, W) uint8 (the
    ``mask_path`` file, else the alpha channel, else None: the whole photo is the object).

    Raises InputError naming the file: unreadable (:func:`mesh2tex.io.images.read_image`), not a
    photo (:data:`NOT_PHOTO_MODES`), smaller than ``MIN_SET_PHOTO_SIDE`` on a side, a mask file that
    is missing, of another size or coloured, or a mask with no object pixel (coverage >= 128)."""
    path = Path(path)
    rgb, alpha = load_image(path)  # first: it names the file for every way of not being an image
    mode = _mode(path)
    if mode in NOT_PHOTO_MODES:
        raise InputError(f"{path}: {NOT_PHOTO_MODES[mode]}, not a photo")
    h, w = rgb.shape[:2]
    if min(h, w) < MIN_SET_PHOTO_SIDE:
        raise InputError(
            f"{path}: the photo is {w}x{h} pixels; a photo of a set needs at least "
            f"{MIN_SET_PHOTO_SIDE}x{MIN_SET_PHOTO_SIDE}"
        )
    where = path
    if mask_path is not None:
        where = Path(mask_path)
        if not where.is_file():
            raise InputError(f"{where}: mask missing for {path.name}")
        alpha = _mask_from_file(where)
        if alpha.shape != (h, w):
            raise InputError(f"{where}: mask is {alpha.shape[1]}x{alpha.shape[0]}, the photo {path.name} {w}x{h}")
    if alpha is not None and not (alpha >= 128).any():
        raise InputError(f"{where}: the mask is empty (no object pixel{'' if mask_path else ' in the alpha channel'})")
    return rgb, alpha


def read_photo_set(items, read=read_set_photo) -> tuple[list, list[str]]:
    """Read every ``(path, mask_path or None)`` of ``items`` with ``read`` (:func:`read_set_photo`);
    returns (what ``read`` returned, for the files it accepted, in order) and the one-line reasons of
    the files it rejected, each naming its file. Nothing stops at the first bad file."""
    kept, rejected = [], []
    for path, mask_path in items:
        try:
            kept.append(read(path, mask_path))
        except InputError as error:
            rejected.append(str(error))
    return kept, rejected


def refuse_rejected(rejected: list[str], total: int, where: str | Path, what: str = "photos") -> None:
    """Stop a command whose photo set holds rejected files with an InputError (the command's one error
    line) that counts them and quotes the first; when there are several, each is printed first as a
    warning line of its own. Nothing when none was rejected."""
    if not rejected:
        return
    if len(rejected) == 1:
        raise InputError(f"{where}: 1 of {total} {what} cannot be used: {rejected[0]}; fix or remove it")
    for line in rejected:
        warning(f"rejected: {one_line(line)}")
    raise InputError(
        f"{where}: {len(rejected)} of {total} {what} cannot be used (each named above), the first: {rejected[0]}; "
        f"fix or remove them"
    )


# ------------------------------------------------------------------------------ photo sets as tensors
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
                raise InputError(
                    f"{folder}: two {what} files share the name '{path.stem}' ({found[path.stem].name}, {path.name})"
                )
            found[path.stem] = path
    if not found:
        raise InputError(f"{folder}: no {what} images ({', '.join(IMAGE_SUFFIXES)})")
    return found


def square_resize(image: torch.Tensor, resolution: int) -> torch.Tensor:
    """Centre-crop [C, H, W] to a square and resize it (antialiased bilinear) to resolution^2."""
    height, width = image.shape[-2:]
    side = min(height, width)
    top, left = (height - side) // 2, (width - side) // 2
    crop = image[:, top : top + side, left : left + side]
    if side == resolution:
        return crop
    return F.interpolate(
        crop[None], size=(resolution, resolution), mode="bilinear", align_corners=False, antialias=True
    )[0]


def load_set(
    folder: str | Path, what: str, resolution: int, background: float, masks: dict[str, Path] | None = None
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """All images of ``folder`` as [N, 3, R, R] in [0, 1], masked-out pixels set to ``background``, and
    their object masks [N, 1, R, R] (0/1) when every image has one (a ``masks`` file or an alpha
    channel), else None. Every file is checked first (:func:`read_set_photo`); any
    rejected one is an InputError counting them, each named (:func:`refuse_rejected`)."""

    def read(path: Path, mask_path: Path | None) -> tuple[torch.Tensor, torch.Tensor | None]:
        rgb, coverage = read_set_photo(path, mask_path)
        image = torch.from_numpy(np.array(rgb)).permute(2, 0, 1).contiguous().float() / 255.0
        if coverage is None:
            return square_resize(image, resolution), None
        mask = torch.from_numpy(coverage >= 128)[None].float()
        return square_resize(composite_images(image, mask, background), resolution), (
            square_resize(mask, resolution) > 0.5
        ).float()

    listed = list_images(folder, what)
    items = [(path, masks.get(stem) if masks is not None else None) for stem, path in listed.items()]
    read_set, rejected = read_photo_set(items, read)
    refuse_rejected(rejected, len(items), folder, f"{what}s")
    images = [image for image, _ in read_set]
    object_masks = [mask for _, mask in read_set if mask is not None]
    return torch.stack(images), (torch.stack(object_masks) if len(object_masks) == len(images) else None)


def load_photo_collection(folder: str | Path, resolution: int) -> torch.Tensor:
    """The GAN's photo collection as uint8 (N, 4, R, R): RGB plus mask (255: object).

    Layouts: ``folder/images/*`` with same-named ``folder/masks/*`` (white = object), or ``folder/*``
    whose alpha channel is the mask (no alpha: the whole image is the object). Every photo is checked
    once (:func:`read_photo_set`) and framed as every set is (:func:`square_resize`); a set with any
    rejected file (unreadable, too small, not a photo, a bad or empty mask, an object smaller than a
    pixel at R x R) is an InputError, each file named.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: images folder not found")
    image_dir = folder / "images" if (folder / "images").is_dir() else folder
    masks = list_images(folder / "masks", "mask") if (folder / "masks").is_dir() else None

    def read(path: Path, mask_path: Path | None) -> torch.Tensor:
        rgb, coverage = read_set_photo(path, mask_path)
        coverage = np.full(rgb.shape[:2], 255, np.uint8) if coverage is None else coverage
        rgba = torch.from_numpy(np.dstack([rgb, coverage])).permute(2, 0, 1).float()
        small = square_resize(rgba, resolution).round().clamp(0, 255).to(torch.uint8)
        if not (small[3] >= 128).any():  # a speck of an object vanishes at the training resolution
            raise InputError(
                f"{mask_path or path}: the object covers no pixel once resized to {resolution}x{resolution}"
            )
        return small

    listed = list_images(image_dir, "image")
    items = [
        (path, None if masks is None else masks.get(stem, folder / "masks" / f"{stem}.png"))
        for stem, path in listed.items()
    ]
    photos, rejected = read_photo_set(items, read)
    refuse_rejected(rejected, len(items), image_dir)
    return torch.stack(photos)
