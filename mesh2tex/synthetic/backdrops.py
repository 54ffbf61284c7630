"""Backdrops for photos of an object: what the mask network learns to tell the object from.

A user's photo shows the object in front of a wall, a floor, furniture, clutter; the world's own
photos have plain, gradient, noise or blurred-photo backgrounds (:func:`mesh2tex.synthetic.world.random_background`).
:func:`backdrop` draws sharper and busier ones: crops of the world's background photographs at
full sharpness, and drawn clutter (rectangles, discs, lines, stripes over a wall colour).
:func:`room` draws the scene most furniture is photographed in: a wall over a floor that recedes to
the horizon, the object standing on the floor with a shadow at its foot.
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


def _hsv(hue: float, saturation: float, value: float) -> np.ndarray:
    return np.array(colorsys.hsv_to_rgb(hue, saturation, value), dtype=np.float32)


def _colour(rng: np.random.Generator, saturation: float = 0.7) -> np.ndarray:
    return _hsv(rng.uniform(0, 1), rng.uniform(0.0, saturation), rng.uniform(0.1, 1.0))


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


def _hashed(index: np.ndarray, salt: float) -> np.ndarray:
    """A fixed pseudo-random value in [0, 1) per integer of ``index`` (a board's or a tile's shade)."""
    return np.modf(np.abs(np.sin(index * 12.9898 + salt) * 43758.5453))[0].astype(np.float32)


def room(rng: np.random.Generator, size: int) -> tuple[np.ndarray, int]:
    """A room: (size, size, 3) float32 in [0, 1] and the row where the floor begins.

    A painted wall lit from above (plain, striped like wallpaper, or with a picture on it) and a
    skirting board, over a floor seen in perspective: boards running away from the camera or across
    it, tiles, or carpet, sometimes under a rug, darker towards the horizon. Drawn at twice the size
    and averaged down, so the far floor's fine lines do not alias."""
    import cv2

    big = 2 * size
    horizon = int(big * rng.uniform(0.2, 0.7))
    rows = np.arange(big, dtype=np.float32)
    paint = _hsv(rng.uniform(0, 1), rng.uniform(0.0, 0.3), rng.uniform(0.4, 0.97))
    image = np.empty((big, big, 3), np.float32)
    image[:] = paint * (0.8 + 0.2 * (1 - rows / big))[:, None, None]
    if rng.random() < 0.3:  # wallpaper stripes
        period = float(rng.uniform(0.02, 0.1) * big)
        image *= (1 + 0.1 * (np.arange(big) % period < period / 2))[None, :, None].astype(np.float32)
    if rng.random() < 0.4:  # a picture or a window
        h, w = (int(v) for v in rng.uniform(0.1, 0.4, 2) * big)
        top, left = int(rng.integers(0, max(1, horizon - h))), int(rng.integers(0, big - w))
        source = _photo(BACKGROUND_PHOTOS[int(rng.integers(len(BACKGROUND_PHOTOS)))])
        picture = cv2.resize(source, (w, min(h, horizon - top)), interpolation=cv2.INTER_AREA) / np.float32(255)
        image[top : top + picture.shape[0], left : left + w] = picture
    skirting = max(1, int(big * rng.uniform(0.0, 0.04)))
    image[max(0, horizon - skirting) : horizon] = _colour(rng, saturation=0.3)
    # the floor: a plane below the camera; row r lies at a depth proportional to 1 / (r - horizon)
    below = rows[horizon:, None] - horizon + 0.5
    across = (np.arange(big, dtype=np.float32)[None, :] - big * np.float32(rng.uniform(0.3, 0.7))) / below
    depth = np.float32(big) / below
    if rng.random() < 0.6:  # wood, from pale oak to walnut
        base = _hsv(rng.uniform(0.04, 0.12), rng.uniform(0.25, 0.7), rng.uniform(0.25, 0.85))
    else:  # stone, linoleum, carpet: muted
        base = _hsv(rng.uniform(0, 1), rng.uniform(0.0, 0.4), rng.uniform(0.2, 0.9))
    pattern = str(rng.choice(["boards", "boards_across", "tiles", "carpet"]))
    unit = float(rng.uniform(0.05, 0.25))
    if pattern == "carpet":
        shade = 1 + 0.08 * rng.standard_normal(across.shape).astype(np.float32)
    else:
        index = np.floor((depth if pattern == "boards_across" else across) / unit)
        shade = 0.8 + 0.35 * _hashed(index, float(rng.uniform(0, 100)))
        if pattern == "tiles":
            shade = np.where((index + np.floor(depth / unit)) % 2 == 0, shade, 1.2 - 0.3 * shade)
    floor = base * (shade * (0.75 + 0.25 * np.minimum(below / big * 3, 1)))[..., None]
    if rng.random() < 0.3:  # a rug
        near, far = sorted(rng.uniform(0.5, 6.0, 2))
        half = float(rng.uniform(0.3, 2.0))
        on_rug = (depth > near) & (depth < far) & (np.abs(across) < half)
        floor = np.where(on_rug[..., None], _colour(rng) * shade[..., None], floor)
    image[horizon:] = floor
    image = cv2.resize(np.clip(image, 0, 1), (size, size), interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(image), horizon // 2


def foot_shadow(alpha: torch.Tensor, strength: float) -> torch.Tensor:
    """The soft shadow an object standing on the floor casts at its foot: a blurred ellipse under the
    lowest tenth of its mask alpha (1, 1, S, S), as a (1, 1, S, S) CPU factor in [1 - strength, 1] to
    multiply the floor by."""
    import cv2

    cover = alpha[0, 0].detach().cpu().numpy() > 0.5  # the views may be on a GPU
    rows, cols = np.nonzero(cover)
    shadow = np.zeros(cover.shape, np.float32)
    if len(rows):
        height = rows.max() - rows.min() + 1
        foot = rows >= rows.max() - height // 10
        centre = (int(cols[foot].mean()), int(rows.max()))
        axes = (max(1, int(0.6 * (cols.max() - cols.min() + 1))), max(1, int(0.06 * height)))
        cv2.ellipse(shadow, centre, axes, 0, 0, 360, 1.0, -1)
        shadow = cv2.GaussianBlur(shadow, (0, 0), max(0.5, 0.03 * height))
    return torch.from_numpy(1 - strength * shadow)[None, None]


def camouflage(scene: torch.Tensor, rgb: torch.Tensor, cover: torch.Tensor) -> torch.Tensor:
    """The scene [1, 3, R, R] in [0, 1] scaled per channel so that its mean colour is the object's (rgb
    [1, 3, S, S] in [0, 1], its coverage ``cover`` [1, 1, S, S]): the same pattern in the object's colours,
    as a brown chair base on brown floorboards, where colour alone does not tell object from floor."""
    weight = cover.sum().clamp_min(1e-6)
    object_mean = (rgb * cover).sum(dim=(0, 2, 3)) / weight
    scene_mean = scene.mean(dim=(0, 2, 3)).clamp_min(1e-3)
    return (scene * (object_mean / scene_mean).view(1, 3, 1, 1)).clamp(0, 1)


def shaded_blob(rng: np.random.Generator, size: int) -> tuple[np.ndarray, np.ndarray]:
    """A rounded thing that is not the object: a smooth star-shaped outline (a disc's radius waved by a few
    low harmonics, stretched and turned) filled with a colour or a crop of a backdrop, shaded as a dome
    under a light from the front (a head, a vase, a cushion, a ball). Returns its (size, size, 3) float32
    colours in [0, 1] and its (size, size) float32 coverage in [0, 1] (edges a pixel soft)."""
    import cv2

    angles = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    radius = np.ones_like(angles)
    for k in range(2, 6):
        radius += rng.uniform(0, 0.25 / k) * np.cos(k * angles + rng.uniform(0, 2 * np.pi))
    scale = size * rng.uniform(0.08, 0.35) * np.exp(rng.uniform(-0.5, 0.5) * np.array([1.0, -1.0]))
    turn = rng.uniform(0, np.pi)
    x, y = radius * np.cos(angles) * scale[0], radius * np.sin(angles) * scale[1]
    centre = rng.uniform(0, size, 2)
    points = np.stack([x * np.cos(turn) - y * np.sin(turn), x * np.sin(turn) + y * np.cos(turn)], 1) + centre
    inside = np.zeros((size, size), np.uint8)
    cv2.fillPoly(inside, [np.round(points).astype(np.int32)], 1)
    # the dome: height from the distance to the outline, its slope the shading's normal
    distance = cv2.distanceTransform(inside, cv2.DIST_L2, 3)
    reach = max(float(distance.max()), 1.0)
    height = reach * np.sqrt(1 - (1 - np.minimum(distance / reach, 1)) ** 2)
    gy, gx = np.gradient(height)
    normal = np.stack([-gx, -gy, np.ones_like(gx)], -1)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    light = np.array([rng.uniform(-0.7, 0.7), rng.uniform(-0.9, 0.2), 1.0])  # image rows grow down: mostly from above
    light /= np.linalg.norm(light)
    ambient = rng.uniform(0.2, 0.5)
    shade = (ambient + (1 - ambient) * np.clip(normal @ light, 0, 1)).astype(np.float32)
    albedo = backdrop(rng, size) if rng.random() < 0.5 else np.broadcast_to(_colour(rng), (size, size, 3))
    cover = cv2.GaussianBlur(inside.astype(np.float32), (0, 0), 0.7)
    # x 1.2: a lit face as bright as the albedo's own colour, not only its shadowed shades
    return np.clip(albedo * shade[..., None] * np.float32(1.2), 0, 1).astype(np.float32), cover


def add_distractors(scene: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``scene`` (S, S, 3) float32 in [0, 1] with one to four :func:`shaded_blob` things drawn over it, behind
    where the object will stand: a photo's other things, which the object's mask must leave out."""
    size = scene.shape[0]
    for _ in range(int(rng.integers(1, 5))):
        colours, cover = shaded_blob(rng, size)
        scene = colours * cover[..., None] + scene * (1 - cover[..., None])
    return np.ascontiguousarray(scene, dtype=np.float32)


def place_over_backdrops(
    images: torch.Tensor,
    masks: torch.Tensor,
    rng: np.random.Generator,
    room_share: float = 0.0,
    camouflage_share: float = 0.0,
    distractor_share: float = 0.0,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Framed views of objects, each shrunk to a random share of the frame (:data:`SCALE_RANGE`), put at
    a random place over a fresh :func:`backdrop`, with a random exposure and a little sensor noise; a
    ``room_share`` of them instead stand on the floor of a :func:`room`, with a shadow at their foot; a
    ``camouflage_share`` of the scenes take the object's mean colour (:func:`camouflage`); a ``distractor_share``
    of them show other rounded things behind the object (:func:`add_distractors`).

    images [B, 3, R, R] in [-1, 1]; masks [B, 1, R, R] in {0, 1}. Returns the new images (same shape
    and range) and their masks (coverage >= 1/2 of the shrunk object). ``room_share``, ``camouflage_share``
    and ``distractor_share`` 0 draw exactly what was drawn before rooms existed.
    """
    batch, _, size, _ = images.shape
    out_images, out_masks = torch.empty_like(images), torch.empty_like(masks)
    for b in range(batch):
        side = max(8, int(round(size * rng.uniform(*SCALE_RANGE))))
        top, left = int(rng.integers(0, size - side + 1)), int(rng.integers(0, size - side + 1))
        rgb = F.interpolate((images[b : b + 1] + 1) / 2, size=(side, side), mode="area")
        cover = F.interpolate(masks[b : b + 1].float(), size=(side, side), mode="area")
        in_room = room_share > 0 and rng.random() < room_share
        if in_room:  # the object stands on the floor: its box's foot between the horizon and the frame's foot
            scene, horizon = room(rng, size)
            foot = int(rng.integers(min(size, max(side, horizon + size // 20)), size + 1))
            top = foot - side
        else:
            scene = backdrop(rng, size)
        if distractor_share > 0 and rng.random() < distractor_share:
            scene = add_distractors(scene, rng)
        canvas = torch.from_numpy(scene).permute(2, 0, 1)[None].to(images)
        if camouflage_share > 0 and rng.random() < camouflage_share:
            canvas = camouflage(canvas, rgb, cover)
        alpha = torch.zeros_like(canvas[:, :1])
        alpha[..., top : top + side, left : left + side] = cover
        if in_room:
            canvas = canvas * foot_shadow(alpha, float(rng.uniform(0.2, 0.6))).to(canvas)
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
