"""A procedural material library: solid (3D) textures that colour any surface point.

A pattern is a function of surface points and normals, ``pattern(points, normals) -> rgb``:
points (N, 3) float64 in the shape's normalised frame, normals (N, 3) unit, rgb (N, 3) float64 in
[0, 1]. Because it depends only on the 3D point, the same pattern renders a "photo" (evaluated at
the per-pixel interpolated positions) and bakes a UV texture (evaluated at the texel positions) with
no seams and no UV distortion. 2D patterns (weave, photographic images) are projected triplanarly.

A :class:`Material` maps part labels (``mesh2tex.synthetic.solids.PART_NAMES``) to patterns;
:func:`random_material` draws a plausible one for a chair or a car. Every pattern describes itself
as JSON (:meth:`describe`) so a world records the ground-truth material of each shape.
"""

from __future__ import annotations

import functools
import typing
from dataclasses import asdict, dataclass, field

import numpy as np

from mesh2tex.synthetic.solids import PART_ID, PART_NAMES

Colour = tuple[float, float, float]

# Palettes (sRGB in [0, 1]) by role.
FABRIC = (
    (0.62, 0.12, 0.12),
    (0.14, 0.24, 0.48),
    (0.22, 0.40, 0.25),
    (0.78, 0.62, 0.30),
    (0.45, 0.45, 0.48),
    (0.85, 0.80, 0.70),
    (0.30, 0.18, 0.38),
    (0.12, 0.12, 0.14),
    (0.85, 0.45, 0.20),
    (0.20, 0.50, 0.55),
)
LEATHER = ((0.35, 0.18, 0.08), (0.10, 0.08, 0.07), (0.55, 0.35, 0.18), (0.75, 0.70, 0.62), (0.45, 0.10, 0.08))
WOOD = (
    ((0.78, 0.58, 0.36), (0.55, 0.35, 0.18)),
    ((0.60, 0.38, 0.20), (0.36, 0.20, 0.09)),
    ((0.88, 0.76, 0.56), (0.68, 0.52, 0.32)),
    ((0.36, 0.22, 0.13), (0.20, 0.11, 0.06)),
)
METAL = ((0.70, 0.71, 0.73), (0.45, 0.46, 0.48), (0.12, 0.12, 0.13), (0.85, 0.85, 0.82))
PLASTIC = ((0.92, 0.92, 0.90), (0.10, 0.10, 0.10), (0.80, 0.20, 0.15), (0.95, 0.75, 0.10), (0.20, 0.45, 0.80))
PAINT = (
    (0.75, 0.08, 0.08),
    (0.08, 0.18, 0.55),
    (0.92, 0.92, 0.92),
    (0.08, 0.08, 0.09),
    (0.60, 0.62, 0.65),
    (0.95, 0.75, 0.05),
    (0.10, 0.40, 0.20),
    (0.95, 0.45, 0.05),
    (0.35, 0.65, 0.85),
    (0.45, 0.05, 0.25),
)
GLASS = ((0.10, 0.13, 0.17), (0.16, 0.22, 0.28), (0.06, 0.07, 0.08))
PHOTO_IMAGES = ("brick", "grass", "gravel")


def _c(values) -> np.ndarray:
    return np.asarray(values, dtype=np.float64)


def _mix(a: Colour, b: Colour, t: np.ndarray) -> np.ndarray:
    """(N,) weights -> (N, 3): a where t = 0, b where t = 1."""
    t = np.clip(t, 0.0, 1.0)[:, None]
    return _c(a)[None] * (1 - t) + _c(b)[None] * t


def _round(colour) -> list[float]:
    return [round(float(v), 3) for v in colour]


class Pattern:
    """Base of all patterns: ``__call__(points (N,3), normals (N,3)) -> rgb (N,3)`` in [0, 1]."""

    def __call__(self, points: np.ndarray, normals: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def describe(self) -> dict:
        """JSON-serialisable description: the kind and its parameters."""
        data = asdict(self) if hasattr(self, "__dataclass_fields__") else {}
        out = {"kind": getattr(self, "KIND", type(self).__name__.lower())}
        for key, value in data.items():
            if isinstance(value, tuple) and value and isinstance(value[0], float):
                value = _round(value)
            elif isinstance(value, float):
                value = round(value, 4)
            out[key] = value
        return out


@dataclass
class Solid(Pattern):
    color: Colour

    def __call__(self, points, normals):
        return np.broadcast_to(_c(self.color), (len(points), 3)).copy()


@dataclass
class Stripes(Pattern):
    """Bands across ``axis`` (a unit 3-vector), ``frequency`` bands per unit length, ``duty`` the share of a."""

    color_a: Colour
    color_b: Colour
    axis: Colour
    frequency: float
    duty: float = 0.5

    def __call__(self, points, normals):
        phase = np.mod(points @ _c(self.axis) * self.frequency, 1.0)
        return _mix(self.color_a, self.color_b, (phase >= self.duty).astype(np.float64))


@dataclass
class Checker(Pattern):
    """A 3D checkerboard of cubes of side ``size``."""

    color_a: Colour
    color_b: Colour
    size: float

    def __call__(self, points, normals):
        # A half-cell offset keeps cell boundaries off the shape's symmetry planes.
        cells = np.floor(points / self.size + 0.5).astype(np.int64).sum(axis=1)
        return _mix(self.color_a, self.color_b, (cells % 2).astype(np.float64))


@dataclass
class Noise(Pattern):
    """Fractal value noise between two colours; ``threshold`` > 0 gives a two-tone camouflage."""

    color_a: Colour
    color_b: Colour
    scale: float  # lattice cells per unit length of the first octave
    octaves: int = 3
    seed: int = 0
    threshold: float = 0.0

    def __call__(self, points, normals):
        n = fractal_noise(points * self.scale, self.octaves, self.seed)
        if self.threshold > 0:
            n = (n > self.threshold).astype(np.float64)
        return _mix(self.color_a, self.color_b, n)


@dataclass
class WoodGrain(Pattern):
    """Growth rings around an axis through the origin, distorted by noise."""

    light: Colour
    dark: Colour
    axis: Colour  # the grain direction (unit)
    rings: float  # rings per unit of radius
    seed: int = 0

    def __call__(self, points, normals):
        axis = _c(self.axis)
        offset = points - _c([0.31, -0.23, 0.17])  # the tree's centre line passes beside the object
        radius = np.linalg.norm(offset - np.outer(offset @ axis, axis), axis=1)
        warp = fractal_noise(points * 4.0, 2, self.seed)
        ring = np.mod(radius * self.rings + 1.5 * warp, 1.0)
        fine = fractal_noise(points * 60.0, 1, self.seed + 1)
        t = ring**3 * 0.85 + 0.15 * fine
        return _mix(self.light, self.dark, t)


@dataclass
class Weave(Pattern):
    """A plain fabric weave (threads over and under), projected triplanarly."""

    color_a: Colour
    color_b: Colour
    frequency: float  # threads per unit length

    def __call__(self, points, normals):
        def weave(u, v):
            fu, fv = u * self.frequency, v * self.frequency
            over = (np.floor(fu) + np.floor(fv)) % 2  # which thread is on top in this cell
            across = np.abs(np.sin(np.pi * fu)) ** 0.5  # the round profile of a thread
            along = np.abs(np.sin(np.pi * fv)) ** 0.5
            return np.where(over > 0, across, along) * 0.8 + 0.2 * over

        return _mix(self.color_a, self.color_b, triplanar(weave, points, normals))


@dataclass
class PhotoPattern(Pattern):
    """A grayscale photograph bundled with scikit-image (brick, grass, gravel), tinted, triplanar."""

    KIND: typing.ClassVar[str] = "photo"  # the kind the world's records name it by

    image: str
    dark: Colour
    light: Colour
    tile: float  # world units covered by one copy of the image

    def __call__(self, points, normals):
        image = photo_image(self.image)

        def lookup(u, v):
            return _sample_mirrored(image, u / self.tile, v / self.tile)

        return _mix(self.dark, self.light, triplanar(lookup, points, normals))


@dataclass
class UpFacing(Pattern):
    """``top`` where the surface faces up (normal y above ``threshold``), else ``sides`` (a car's roof over its
    windows)."""

    top: Pattern
    sides: Pattern
    threshold: float = 0.97  # a flat roof, not a sloping windscreen

    def __call__(self, points, normals):
        up = normals[:, 1] > self.threshold
        out = self.sides(points, normals)
        if up.any():
            out[up] = self.top(points[up], normals[up])
        return out

    def describe(self):
        return {
            "kind": "upfacing",
            "top": self.top.describe(),
            "sides": self.sides.describe(),
            "threshold": self.threshold,
        }


@dataclass
class Material:
    """Part-wise patterns: ``parts`` maps a part name to its pattern; ``default`` colours the rest."""

    parts: dict[str, Pattern] = field(default_factory=dict)
    default: Pattern = field(default_factory=lambda: Solid((0.5, 0.5, 0.5)))

    def __call__(self, points: np.ndarray, normals: np.ndarray, part_ids: np.ndarray) -> np.ndarray:
        """points (N,3) float, normals (N,3) float, part_ids (N,) int (PART_NAMES index) -> rgb (N,3) float64 in
        [0,1]."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        part_ids = np.asarray(part_ids).reshape(-1)
        out = np.empty((len(points), 3), dtype=np.float64)
        done = np.zeros(len(points), dtype=bool)
        for name, pattern in self.parts.items():
            rows = part_ids == PART_ID[name]
            if rows.any():
                out[rows] = pattern(points[rows], normals[rows])
                done |= rows
        if not done.all():
            out[~done] = self.default(points[~done], normals[~done])
        return np.clip(out, 0.0, 1.0)

    def describe(self) -> dict:
        return {"parts": {name: p.describe() for name, p in self.parts.items()}, "default": self.default.describe()}


# ----------------------------------------------------------------------------------------------
# Building blocks


def fractal_noise(points: np.ndarray, octaves: int, seed: int) -> np.ndarray:
    """Value noise in [0, 1]: (N, 3) points in lattice units -> (N,), ``octaves`` octaves of halving weight."""
    table = _permutation(seed)
    total = np.zeros(len(points))
    weight_sum = 0.0
    for octave in range(octaves):
        scale = 2.0**octave
        weight = 0.5**octave
        total += weight * _value_noise(points * scale + 17.0 * octave, table)
        weight_sum += weight
    return total / weight_sum


@functools.lru_cache(maxsize=64)
def _permutation(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).permutation(256).astype(np.int64)


def _value_noise(points: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Trilinear interpolation (smoothstep-eased) of random values on the integer lattice: (N,3) -> (N,)."""
    base = np.floor(points)
    frac = points - base
    frac = frac * frac * (3 - 2 * frac)
    corner = base.astype(np.int64)
    out = np.zeros(len(points))
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                h = table[(corner[:, 0] + dx) & 255]
                h = table[(h + corner[:, 1] + dy) & 255]
                h = table[(h + corner[:, 2] + dz) & 255]
                w = (
                    (frac[:, 0] if dx else 1 - frac[:, 0])
                    * (frac[:, 1] if dy else 1 - frac[:, 1])
                    * (frac[:, 2] if dz else 1 - frac[:, 2])
                )
                out += w * (h / 255.0)
    return out


def triplanar(function, points: np.ndarray, normals: np.ndarray, sharpness: float = 4.0) -> np.ndarray:
    """Blend a 2D function ``function(u, v) -> (N,)`` projected along x, y and z by |normal|^sharpness."""
    weights = np.abs(normals) ** sharpness
    weights /= np.maximum(weights.sum(axis=1, keepdims=True), 1e-12)
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    return weights[:, 0] * function(z, y) + weights[:, 1] * function(x, z) + weights[:, 2] * function(x, y)


@functools.lru_cache(maxsize=8)
def photo_image(name: str) -> np.ndarray:
    """A bundled scikit-image photograph as (H, W) float64 in [0, 1], contrast-stretched."""
    import skimage.data

    if name not in PHOTO_IMAGES:
        raise ValueError(f"unknown photo texture {name!r}; choose one of {', '.join(PHOTO_IMAGES)}")
    image = np.asarray(getattr(skimage.data, name)(), dtype=np.float64)
    if image.ndim == 3:
        image = image[..., :3].mean(axis=2)
    low, high = np.percentile(image, [1, 99])
    return np.clip((image - low) / max(high - low, 1e-6), 0, 1)


def _sample_mirrored(image: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear lookup at (u, v) in image units (1 = one copy), mirrored repeat so copies join without seams."""
    h, w = image.shape

    def mirror(t, size):
        t = np.mod(t, 2.0)
        t = np.where(t > 1.0, 2.0 - t, t)
        return t * (size - 1)

    x, y = mirror(u, w), mirror(v, h)
    x0 = np.clip(np.floor(x).astype(np.int64), 0, w - 2)
    y0 = np.clip(np.floor(y).astype(np.int64), 0, h - 2)
    fx, fy = x - x0, y - y0
    top = image[y0, x0] * (1 - fx) + image[y0, x0 + 1] * fx
    bottom = image[y0 + 1, x0] * (1 - fx) + image[y0 + 1, x0 + 1] * fx
    return top * (1 - fy) + bottom * fy


# ----------------------------------------------------------------------------------------------
# Random materials


def _pick(rng: np.random.Generator, options):
    return options[int(rng.integers(len(options)))]


def _jitter(rng: np.random.Generator, colour, amount: float = 0.06) -> Colour:
    return tuple(float(v) for v in np.clip(_c(colour) + rng.uniform(-amount, amount, 3), 0, 1))


def _shade(colour, factor: float) -> Colour:
    return tuple(float(v) for v in np.clip(_c(colour) * factor, 0, 1))


def _random_axis(rng: np.random.Generator) -> Colour:
    axis = np.zeros(3)
    axis[int(rng.integers(3))] = 1.0
    axis += rng.normal(0, 0.15, 3)
    return tuple(float(v) for v in axis / np.linalg.norm(axis))


def random_upholstery(rng: np.random.Generator) -> Pattern:
    """A seat or back covering: fabric, weave, leather, stripes, plaid, photographic or wood."""
    kind = _pick(rng, ("solid", "weave", "leather", "stripes", "checker", "photo", "wood", "noise"))
    base = _jitter(rng, _pick(rng, FABRIC))
    if kind == "solid":
        return Solid(base)
    if kind == "weave":
        return Weave(_shade(base, 0.6), base, float(rng.uniform(40, 90)))
    if kind == "leather":
        leather = _jitter(rng, _pick(rng, LEATHER), 0.04)
        return Noise(_shade(leather, 0.75), leather, float(rng.uniform(15, 30)), 3, int(rng.integers(1 << 16)))
    if kind == "stripes":
        return Stripes(
            base,
            _jitter(rng, _pick(rng, FABRIC)),
            _random_axis(rng),
            float(rng.uniform(6, 18)),
            float(rng.uniform(0.3, 0.7)),
        )
    if kind == "checker":
        return Checker(base, _jitter(rng, _pick(rng, FABRIC)), float(rng.uniform(0.04, 0.12)))
    if kind == "photo":
        return random_photo(rng, base)
    if kind == "wood":
        return random_wood(rng)
    return Noise(_shade(base, 0.55), base, float(rng.uniform(4, 12)), 4, int(rng.integers(1 << 16)))


def random_photo(rng: np.random.Generator, tint: Colour) -> PhotoPattern:
    """A photographic texture tinted from dark to ``tint``-light."""
    name = _pick(rng, PHOTO_IMAGES)
    light = tuple(float(v) for v in np.clip(_c(tint) * 0.5 + 0.5, 0, 1))
    return PhotoPattern(name, _shade(tint, 0.35), light, float(rng.uniform(0.25, 0.6)))


def random_wood(rng: np.random.Generator) -> WoodGrain:
    light, dark = _pick(rng, WOOD)
    return WoodGrain(
        _jitter(rng, light, 0.04),
        _jitter(rng, dark, 0.03),
        _random_axis(rng),
        float(rng.uniform(25, 60)),
        int(rng.integers(1 << 16)),
    )


def random_frame(rng: np.random.Generator) -> Pattern:
    """Legs and frames: wood, metal or plastic."""
    kind = _pick(rng, ("wood", "wood", "metal", "plastic"))
    if kind == "wood":
        return random_wood(rng)
    if kind == "metal":
        metal = _jitter(rng, _pick(rng, METAL), 0.03)
        return Noise(_shade(metal, 0.85), metal, 30.0, 2, int(rng.integers(1 << 16)))
    return Solid(_jitter(rng, _pick(rng, PLASTIC), 0.03))


def random_chair_material(rng: np.random.Generator) -> Material:
    cover = random_upholstery(rng)
    back = cover if rng.random() < 0.75 else random_upholstery(rng)
    frame = random_frame(rng)
    arm = frame if rng.random() < 0.6 else cover
    base = frame if rng.random() < 0.5 else Solid(_jitter(rng, _pick(rng, METAL), 0.03))
    return Material({"seat": cover, "back": back, "leg": frame, "arm": arm, "base": base}, default=frame)


def random_paint(rng: np.random.Generator) -> Pattern:
    """Car body paint: plain, racing stripes, two-tone, checks, camouflage or weathered (photographic)."""
    paint = _jitter(rng, _pick(rng, PAINT), 0.04)
    kind = _pick(rng, ("solid", "solid", "solid", "stripes", "twotone", "checker", "camo", "photo"))
    other = _jitter(rng, _pick(rng, PAINT), 0.04)
    if kind == "solid":
        return Solid(paint)
    if kind == "stripes":  # stripes running front to back
        return Stripes(paint, other, (1.0, 0.0, 0.0), float(rng.uniform(2, 6)), float(rng.uniform(0.55, 0.85)))
    if kind == "twotone":  # a lower and an upper colour
        return Stripes(paint, other, (0.0, 1.0, 0.0), 1.0, float(rng.uniform(0.35, 0.6)))
    if kind == "checker":
        return Checker(paint, other, float(rng.uniform(0.05, 0.12)))
    if kind == "camo":
        return Noise(paint, _shade(paint, 0.5), float(rng.uniform(5, 10)), 3, int(rng.integers(1 << 16)), threshold=0.5)
    return random_photo(rng, paint)


def random_car_material(rng: np.random.Generator) -> Material:
    paint = random_paint(rng)
    glass = Solid(_jitter(rng, _pick(rng, GLASS), 0.02))
    tyre = Noise((0.05, 0.05, 0.05), (0.14, 0.14, 0.15), 40.0, 2, int(rng.integers(1 << 16)))
    hub = Solid(_jitter(rng, _pick(rng, METAL), 0.03))
    return Material(
        {
            "body": paint,
            "cabin": UpFacing(paint, glass),
            "wheel": tyre,
            "hub": hub,
            "headlight": Solid(_jitter(rng, (0.95, 0.93, 0.80), 0.03)),
            "taillight": Solid(_jitter(rng, (0.80, 0.08, 0.06), 0.03)),
        },
        default=paint,
    )


def random_material(category: str, rng: np.random.Generator) -> Material:
    """A random part-wise material for a 'chair' or a 'car', drawn from ``rng`` only."""
    if category == "chair":
        return random_chair_material(rng)
    if category == "car":
        return random_car_material(rng)
    raise ValueError(f"unknown category {category!r}")


__all__ = [
    "Pattern",
    "Solid",
    "Stripes",
    "Checker",
    "Noise",
    "WoodGrain",
    "Weave",
    "PhotoPattern",
    "UpFacing",
    "Material",
    "fractal_noise",
    "triplanar",
    "photo_image",
    "random_material",
    "PART_NAMES",
]
