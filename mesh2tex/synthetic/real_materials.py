"""Materials a photo would show, for the varied world (``prepare synthetic --variety real``).

Wood with grain, fabric with weave, leather, upholstery with seams, painted and brushed metal,
plastic, tyre rubber and dark glass, each a :class:`~mesh2tex.synthetic.materials.Pattern` whose
parameters are **physical**: frequencies in cycles per metre on the object, widths in metres. A
shape of the world lives in the normalised frame (bounding-box diagonal 1); :func:`metres_per_unit`
recovers its size in metres from the design it was built from (its ``params``), and
:class:`AtScale` evaluates a metric pattern at ``points * metres``.

**Band limit.** A chair's photo at 128 px resolves about 2 cm; a fabric's threads are 1 mm apart.
Evaluated point by point, detail finer than the pixels would alias into speckle, the very thing the
world's photos must not teach a generator. So every pattern takes ``limit``, the finest frequency
(cycles per metre) its renders resolve, and fades each of its components from full contrast at
``limit / 2`` to its mean at ``limit`` (:func:`fade`); a thin line (a seam) keeps its integrated
contrast and widens to what is resolved. :func:`real_material` sets ``limit`` to
:data:`LIMIT_PER_UNIT` cycles per object diagonal; ``limit = inf`` keeps every detail (the tests
check the weave and the grain that way).

The albedo statistics and spatial frequencies of each material are in ``docs/synthetic.md``
("Materials of the varied world"), with the speckle share the generation benchmark measures.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mesh2tex.synthetic.materials import (
    GLASS, LEATHER, METAL, PAINT, Colour, Material, Pattern, Solid, UpFacing, _c, _jitter, _mix, _permutation, _pick,
    _value_noise, triplanar,
)
from mesh2tex.synthetic.shapes import SyntheticShape
from mesh2tex.synthetic.solids import PART_ID

LIMIT_PER_UNIT = 64.0  # cycles per object diagonal the world's renders resolve (256 px renders span ~200 px per diagonal)
TYPICAL_METRES = {"chair": 1.2, "car": 5.0}  # a bounding-box diagonal when the shape is not known

# Palettes (sRGB in [0, 1]). Wood: (light, dark) pairs of oak, walnut, beech/birch, cherry, ash, stained black.
WOODS = (((0.74, 0.56, 0.36), (0.52, 0.36, 0.20)), ((0.42, 0.28, 0.18), (0.24, 0.15, 0.09)),
         ((0.86, 0.72, 0.54), (0.70, 0.55, 0.38)), ((0.66, 0.38, 0.24), (0.45, 0.23, 0.13)),
         ((0.84, 0.76, 0.62), (0.62, 0.52, 0.40)), ((0.16, 0.14, 0.13), (0.08, 0.07, 0.07)))
# Upholstery fabrics: greys, navy, bottle green, mustard, rust, oatmeal, charcoal, teal, burgundy, sand.
FABRICS = ((0.55, 0.55, 0.56), (0.16, 0.22, 0.38), (0.18, 0.33, 0.24), (0.74, 0.58, 0.22), (0.62, 0.30, 0.18),
           (0.78, 0.73, 0.64), (0.22, 0.22, 0.24), (0.16, 0.40, 0.42), (0.42, 0.10, 0.14), (0.70, 0.62, 0.48))
PLASTICS = ((0.93, 0.93, 0.91), (0.10, 0.10, 0.10), (0.80, 0.22, 0.16), (0.92, 0.74, 0.16), (0.22, 0.44, 0.72),
            (0.55, 0.66, 0.58), (0.85, 0.60, 0.55))
RUBBER = (0.16, 0.16, 0.17)
_WEAVE_MEAN = 0.7043  # the mean of |sin(pi x)|^0.7, the weave's brightness


def fade(frequency: float, limit: float) -> float:
    """Contrast kept by a component of ``frequency`` (cycles per metre) under the band ``limit``: 1 up to
    ``limit / 2``, falling linearly to 0 at ``limit`` (``limit`` inf: 1)."""
    if not math.isfinite(limit):
        return 1.0
    return float(np.clip(2.0 - 2.0 * frequency / limit, 0.0, 1.0))


def banded_noise(coords: np.ndarray, frequency: float, octaves: int, seed: int, limit: float, gain: float = 0.5) -> np.ndarray:
    """Value noise in [0, 1] with each octave faded by the band limit: coords (N, 3) in lattice units of
    the first octave, whose finest frequency is ``frequency`` cycles per metre -> (N,). A faded octave
    adds its mean (1/2), so the mean stays 1/2 and the contrast shrinks."""
    table = _permutation(seed)
    total = np.zeros(len(coords))
    weights = 0.0
    for octave in range(octaves):
        weight = gain**octave
        keep = fade(frequency * 2.0**octave, limit)
        if keep > 0:
            total += weight * keep * (_value_noise(coords * 2.0**octave + 17.0 * octave, table) - 0.5)
        weights += weight
    return 0.5 + total / weights


def _frame(axis) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A unit ``axis`` and two unit vectors perpendicular to it and to each other."""
    a = _c(axis) / np.linalg.norm(axis)
    other = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    b = np.cross(a, other)
    b /= np.linalg.norm(b)
    return a, b, np.cross(a, b)


def _line(distance: np.ndarray, width: float, limit: float) -> np.ndarray:
    """A line's profile (N,) in [0, 1] at ``distance`` metres from its centre: a Gaussian of ``width``,
    widened to the band limit with its integral kept (a seam finer than a pixel darkens it a little)."""
    resolved = 1.0 / limit if math.isfinite(limit) else 0.0
    drawn = max(width, resolved)
    return (width / drawn) * np.exp(-0.5 * (distance / (0.4 * drawn)) ** 2)


class _Metric(Pattern):
    """A pattern in metres: describes its floats rounded to 4 significant figures (small widths survive)."""

    def describe(self) -> dict:
        out = super().describe()
        for key, value in list(out.items()):
            if isinstance(value, float):
                out[key] = float(f"{getattr(self, key):.4g}") if math.isfinite(getattr(self, key)) else "inf"
        return out


@dataclass
class Grain(_Metric):
    """Wood: streaks that run along ``axis`` (the grain), ``across`` cycles per metre across it and ``along``
    along it, and growth rings seen as lines ``rings`` per metre across the grain, warped by the streaks."""

    KIND = "grain"
    light: Colour
    dark: Colour
    axis: Colour  # unit grain direction in the shape's frame
    across: float = 15.0  # streaks per metre across the grain (the figure of a flat-sawn board: bands 4-12 cm apart)
    along: float = 2.0  # streak variation per metre along the grain
    rings: float = 250.0  # growth-ring lines per metre across the grain (2-8 mm apart)
    seed: int = 0
    limit: float = math.inf  # band limit, cycles per metre

    def __call__(self, points, normals):
        a, b, c = _frame(self.axis)
        u, v, w = points @ a, points @ b, points @ c
        streaks = banded_noise(np.stack([u * self.along, v * self.across, w * self.across], axis=1), self.across, 3, self.seed, self.limit)
        phase = (v + 0.6 * w) * self.rings + 6.0 * streaks
        ring = (0.5 + 0.5 * np.cos(2 * np.pi * phase)) ** 4  # thin dark latewood lines
        t = 0.5 + 3.0 * (streaks - 0.5) + 0.35 * fade(self.rings, self.limit) * (ring - 0.2)
        return _mix(self.light, self.dark, t)


@dataclass
class Fabric(_Metric):
    """A woven fabric: a plain weave of ``threads`` per metre (projected triplanarly), yarn colour varying
    ``heather`` strong at ``yarn`` cycles per metre, and a soft nap at ``nap`` cycles per metre."""

    KIND = "fabric"
    colour: Colour
    threads: float = 700.0  # threads per metre (1-2.5 mm apart)
    weave_contrast: float = 0.35  # darkening in the gaps between threads, share of the colour
    heather: float = 0.10  # yarn-to-yarn colour variation, share of the colour
    yarn: float = 150.0  # cycles per metre of the yarn variation
    nap: float = 8.0  # cycles per metre of the nap's shading
    seed: int = 0
    limit: float = math.inf

    def weave(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The weave's brightness (N,) in [0, 1] at (u, v) metres in the cloth: threads over and under, round."""
        fu, fv = u * self.threads, v * self.threads
        over = (np.floor(fu) + np.floor(fv)) % 2
        across = np.abs(np.sin(np.pi * fu)) ** 0.7
        along = np.abs(np.sin(np.pi * fv)) ** 0.7
        return np.where(over > 0, across, along)

    def __call__(self, points, normals):
        keep = fade(self.threads, self.limit)
        weave = triplanar(self.weave, points, normals) if keep > 0 else np.full(len(points), _WEAVE_MEAN)
        brightness = 1.0 - self.weave_contrast * (1.0 - (_WEAVE_MEAN + keep * (weave - _WEAVE_MEAN)))  # the faded weave keeps its mean
        yarn = banded_noise(points * self.yarn, self.yarn, 2, self.seed, self.limit)
        nap = banded_noise(points * self.nap, self.nap, 2, self.seed + 1, self.limit)
        brightness = brightness * (1.0 + self.heather * 2.0 * (yarn - 0.5)) * (1.0 + 0.3 * (nap - 0.5))
        return np.clip(_c(self.colour)[None] * brightness[:, None], 0.0, 1.0)


@dataclass
class Leather(_Metric):
    """Leather: a pebbled grain of ``pebbles`` cells per metre, mottling at ``mottle`` cycles per metre,
    and creases (soft darker folds) at ``creases`` cycles per metre."""

    KIND = "leather"
    colour: Colour
    pebbles: float = 500.0
    pebble_contrast: float = 0.12
    mottle: float = 12.0
    mottle_contrast: float = 0.12
    creases: float = 4.0
    seed: int = 0
    limit: float = math.inf

    def __call__(self, points, normals):
        pebble = banded_noise(points * self.pebbles, self.pebbles, 1, self.seed, self.limit)
        mottle = banded_noise(points * self.mottle, self.mottle, 3, self.seed + 1, self.limit)
        crease = banded_noise(points * self.creases * np.array([1.0, 3.0, 1.0]), self.creases * 3.0, 2, self.seed + 2, self.limit)
        brightness = (1.0 + self.pebble_contrast * 2.0 * (pebble - 0.5)) * (1.0 + self.mottle_contrast * 2.0 * (mottle - 0.5))
        brightness *= 1.0 - 0.15 * np.clip((crease - 0.55) * 4.0, 0.0, 1.0)
        return np.clip(_c(self.colour)[None] * brightness[:, None], 0.0, 1.0)


@dataclass
class Seams(_Metric):
    """Upholstery: a ``cover`` (fabric or leather) sewn in panels ``panel`` metres wide along x (left to
    right) and, with ``channels`` > 0, in channels that far apart along y; each seam a darker line
    ``width`` metres wide with a lighter roll beside it (the stuffing pushes the cloth up)."""

    KIND = "seams"
    cover: Pattern
    panel: float = 0.25
    channels: float = 0.0
    width: float = 0.006
    depth: float = 0.45  # darkening at a seam's centre, share of the colour
    limit: float = math.inf

    def __call__(self, points, normals):
        out = self.cover(points, normals)
        dark = np.zeros(len(points))
        for coordinate, spacing in ((points[:, 0], self.panel), (points[:, 1], self.channels)):
            if spacing > 0:
                offset = np.mod(coordinate + spacing / 2, spacing) - spacing / 2  # the panel centre line at x = 0
                distance = spacing / 2 - np.abs(offset)  # metres to the nearest seam
                dark = np.maximum(dark, _line(distance, self.width, self.limit))
                roll = _line(distance - 2.0 * self.width, 2.5 * self.width, self.limit)
                dark -= 0.25 * roll
        return np.clip(out * (1.0 - self.depth * dark)[:, None], 0.0, 1.0)

    def describe(self):
        out = super().describe()
        out["cover"] = self.cover.describe()
        return out


@dataclass
class BrushedMetal(_Metric):
    """Brushed steel or aluminium: fine streaks along ``axis`` (``across`` per metre across it, nearly
    constant along it) over a soft sheen at ``sheen`` cycles per metre."""

    KIND = "brushed_metal"
    colour: Colour
    axis: Colour
    across: float = 1500.0
    along: float = 3.0
    streak_contrast: float = 0.10
    sheen: float = 6.0
    seed: int = 0
    limit: float = math.inf

    def __call__(self, points, normals):
        a, b, c = _frame(self.axis)
        u, v, w = points @ a, points @ b, points @ c
        streak = banded_noise(np.stack([u * self.along, v * self.across, w * self.across], axis=1), self.across, 2, self.seed, self.limit)
        sheen = banded_noise(points * self.sheen, self.sheen, 2, self.seed + 1, self.limit)
        brightness = (1.0 + self.streak_contrast * 2.0 * (streak - 0.5)) * (1.0 + 0.16 * (sheen - 0.5))
        return np.clip(_c(self.colour)[None] * brightness[:, None], 0.0, 1.0)


@dataclass
class Painted(_Metric):
    """Paint (painted metal, moulded plastic): one colour with a faint orange peel at ``peel`` cycles per
    metre and a broad variation of the finish at ``finish`` cycles per metre."""

    KIND = "painted"
    colour: Colour
    peel: float = 400.0
    peel_contrast: float = 0.03
    finish: float = 3.0
    finish_contrast: float = 0.05
    seed: int = 0
    limit: float = math.inf

    def __call__(self, points, normals):
        peel = banded_noise(points * self.peel, self.peel, 1, self.seed, self.limit)
        finish = banded_noise(points * self.finish, self.finish, 2, self.seed + 1, self.limit)
        brightness = (1.0 + self.peel_contrast * 2.0 * (peel - 0.5)) * (1.0 + self.finish_contrast * 2.0 * (finish - 0.5))
        return np.clip(_c(self.colour)[None] * brightness[:, None], 0.0, 1.0)


@dataclass
class Rubber(_Metric):
    """Tyre rubber: the tread (surfaces facing away from the axle, x) grooved every ``groove`` metres along x;
    the sidewalls (facing along x) a little lighter, with a faint ring pattern."""

    KIND = "rubber"
    colour: Colour = RUBBER
    groove: float = 0.035
    groove_width: float = 0.008
    sidewall_lift: float = 0.35  # the sidewall's extra brightness, share of the colour
    seed: int = 0
    limit: float = math.inf

    def __call__(self, points, normals):
        side = np.clip((np.abs(normals[:, 0]) - 0.5) * 4.0, 0.0, 1.0)  # 1 on the sidewalls
        offset = np.mod(points[:, 0] + self.groove / 2, self.groove) - self.groove / 2
        groove = _line(np.abs(offset), self.groove_width, self.limit)
        wear = banded_noise(points * 20.0, 20.0, 2, self.seed, self.limit)
        brightness = (1.0 - 0.5 * groove * (1 - side)) * (1.0 + self.sidewall_lift * side) * (1.0 + 0.2 * (wear - 0.5))
        return np.clip(_c(self.colour)[None] * brightness[:, None], 0.0, 1.0)


@dataclass
class DarkGlass(_Metric):
    """Tinted glass seen from outside: dark, a little lighter towards its top (the sky it reflects),
    ``sky`` the lift at the top, over ``height`` metres."""

    KIND = "dark_glass"
    colour: Colour
    sky: float = 0.6
    height: float = 1.6
    limit: float = math.inf

    def __call__(self, points, normals):
        t = np.clip(points[:, 1] / self.height + 0.5, 0.0, 1.0) ** 2
        return np.clip(_c(self.colour)[None] * (1.0 + self.sky * t)[:, None], 0.0, 1.0)


@dataclass
class AtScale(Pattern):
    """``pattern`` (in metres) on a shape in the normalised frame: evaluated at ``points * metres``."""

    KIND = "at_scale"
    pattern: Pattern
    metres: float  # metres per unit of the normalised frame (the shape's bounding-box diagonal)

    def __call__(self, points, normals):
        return self.pattern(np.asarray(points, dtype=np.float64) * self.metres, normals)

    def describe(self):
        return {"kind": self.KIND, "metres": round(float(self.metres), 4), "pattern": self.pattern.describe()}


# ----------------------------------------------------------------------------------------------
# The shape's size, and materials chosen per part


def metres_per_unit(shape: SyntheticShape | None, category: str) -> float:
    """The shape's bounding-box diagonal in metres (the varied world's designs are in metres and record
    their dimensions): a car's ``length`` over its extent along z; a shell chair's ``width`` over its
    extent along x; any other chair's ``seat_height`` over the height of its seat's top above the floor.
    Within 5 % of the true diagonal on the varied world; :data:`TYPICAL_METRES` when ``shape`` is None
    or records none of these."""
    if shape is None:
        return TYPICAL_METRES[category]
    params, v = shape.params, shape.vertices
    if category == "car" and "length" in params:
        return float(params["length"]) / float(np.ptp(v[:, 2]))
    if params.get("family") == "shell" and "width" in params:
        return float(params["width"]) / float(np.ptp(v[:, 0]))
    seat = shape.face_parts == PART_ID["seat"]
    if "seat_height" in params and seat.any():
        top = v[shape.faces[seat]][..., 1].max() - v[:, 1].min()
        return float(params["seat_height"]) / float(top)
    return TYPICAL_METRES[category]


def _seed(rng: np.random.Generator) -> int:
    return int(rng.integers(1 << 16))


def _axis(rng: np.random.Generator, main: int) -> Colour:
    axis = np.zeros(3)
    axis[main] = 1.0
    axis += rng.normal(0, 0.05, 3)
    return tuple(float(x) for x in axis / np.linalg.norm(axis))


def wood(rng: np.random.Generator, limit: float, axis: int = 1, species=None) -> Grain:
    """A wood of ``species`` (an entry of WOODS, else drawn), grain along coordinate ``axis`` (0 x, 1 y, 2 z)."""
    light, dark = species if species is not None else _pick(rng, WOODS)
    return Grain(_jitter(rng, light, 0.03), _jitter(rng, dark, 0.02), _axis(rng, axis), float(rng.uniform(8, 25)),
                 float(rng.uniform(1, 4)), float(rng.uniform(150, 400)), _seed(rng), limit)


def fabric(rng: np.random.Generator, limit: float) -> Fabric:
    return Fabric(_jitter(rng, _pick(rng, FABRICS), 0.04), float(rng.uniform(400, 1000)), float(rng.uniform(0.2, 0.45)),
                  float(rng.uniform(0.04, 0.14)), float(rng.uniform(80, 250)), float(rng.uniform(4, 12)), _seed(rng), limit)


def leather(rng: np.random.Generator, limit: float) -> Leather:
    return Leather(_jitter(rng, _pick(rng, LEATHER), 0.03), float(rng.uniform(300, 800)), float(rng.uniform(0.06, 0.16)),
                   float(rng.uniform(6, 20)), float(rng.uniform(0.06, 0.16)), float(rng.uniform(2, 6)), _seed(rng), limit)


def metal(rng: np.random.Generator, limit: float, axis: int = 1) -> Pattern:
    """Brushed steel or aluminium, or painted metal (black, white or a colour), half and half."""
    if rng.random() < 0.5:
        return BrushedMetal(_jitter(rng, _pick(rng, METAL[:2] + METAL[3:]), 0.03), _axis(rng, axis), float(rng.uniform(800, 2500)),
                            float(rng.uniform(1, 5)), float(rng.uniform(0.05, 0.15)), float(rng.uniform(3, 10)), _seed(rng), limit)
    return painted(rng, limit, _pick(rng, ((0.10, 0.10, 0.11), (0.90, 0.90, 0.88)) + PAINT[:4]))


def painted(rng: np.random.Generator, limit: float, colour: Colour) -> Painted:
    return Painted(_jitter(rng, colour, 0.03), float(rng.uniform(200, 600)), float(rng.uniform(0.01, 0.04)),
                   float(rng.uniform(1, 5)), float(rng.uniform(0.02, 0.08)), _seed(rng), limit)


def plastic(rng: np.random.Generator, limit: float) -> Painted:
    """Moulded plastic: a colour of PLASTICS with a fine stipple and a slight variation of its finish."""
    return painted(rng, limit, _pick(rng, PLASTICS))


def cover(rng: np.random.Generator, limit: float, seams: bool) -> Pattern:
    """A seat or back cover: fabric (60 %) or leather, sewn in panels (and channels, a third of the time) when ``seams``."""
    cloth = fabric(rng, limit) if rng.random() < 0.6 else leather(rng, limit)
    if not seams:
        return cloth
    channels = float(rng.uniform(0.08, 0.16)) if rng.random() < 1 / 3 else 0.0
    return Seams(cloth, float(rng.uniform(0.15, 0.45)), channels, float(rng.uniform(0.004, 0.008)), float(rng.uniform(0.3, 0.55)), limit)


def real_chair_material(rng: np.random.Generator, shape: SyntheticShape | None = None) -> Material:
    """Parts as a real chair of the shape's family has them: legs and frames of wood or metal; seats and
    backs of fabric or leather (upholstered families, with seams), or of the frame's wood, or of
    plastic (shell chairs); an office chair's star base of plastic or brushed metal."""
    metres = metres_per_unit(shape, "chair")
    limit = LIMIT_PER_UNIT / metres
    family = (shape.params.get("family") if shape is not None else None) or "four_legged"
    upholstered = bool(shape.params.get("upholstered")) if shape is not None else False
    species = _pick(rng, WOODS)
    frame = wood(rng, limit, 1, species) if rng.random() < 0.6 else metal(rng, limit, 1)
    if family in ("armchair", "sofa"):
        seat = back = cover(rng, limit, seams=True)
        arm = seat if rng.random() < 0.8 else frame
        legs = wood(rng, limit, 1, species) if rng.random() < 0.7 else metal(rng, limit, 1)
        parts = {"seat": seat, "back": back, "arm": arm, "leg": legs, "base": legs}
    elif family == "office":
        seat = cover(rng, limit, seams=rng.random() < 0.5)
        back = seat if rng.random() < 0.7 else fabric(rng, limit)
        base = plastic(rng, limit) if rng.random() < 0.5 else metal(rng, limit, 0)
        parts = {"seat": seat, "back": back, "arm": plastic(rng, limit), "leg": base, "base": base}
    elif family == "shell":
        shell = plastic(rng, limit) if rng.random() < 0.75 else wood(rng, limit, 2, species)
        parts = {"seat": shell, "back": shell, "arm": shell, "leg": frame, "base": frame}
    else:  # four-legged, stool, bench, rocking, folding, classic: wooden or upholstered seats
        draw = rng.random()
        if upholstered or draw < 0.35:
            seat = cover(rng, limit, seams=rng.random() < 0.4)
        elif draw < 0.85 or not isinstance(frame, Grain):
            seat = wood(rng, limit, 2, species) if isinstance(frame, Grain) or rng.random() < 0.5 else plastic(rng, limit)
        else:
            seat = plastic(rng, limit)
        back = seat if rng.random() < 0.7 else (wood(rng, limit, 1, species) if isinstance(frame, Grain) else frame)
        parts = {"seat": seat, "back": back, "leg": frame, "arm": frame, "base": frame}
    return Material({name: AtScale(p, metres) for name, p in parts.items()}, default=AtScale(frame, metres))


def real_car_material(rng: np.random.Generator, shape: SyntheticShape | None = None) -> Material:
    """A car: painted metal body (and roof), dark glass windows, rubber tyres, brushed or painted hubs,
    clear headlights and red tail lights."""
    metres = metres_per_unit(shape, "car")
    limit = LIMIT_PER_UNIT / metres
    body = painted(rng, limit, _pick(rng, PAINT))
    glass = DarkGlass(_jitter(rng, _pick(rng, GLASS), 0.02), float(rng.uniform(0.3, 0.9)), 1.6, limit)
    hub = metal(rng, limit, 0)
    tyre = Rubber(_jitter(rng, RUBBER, 0.01), float(rng.uniform(0.025, 0.045)), float(rng.uniform(0.005, 0.012)),
                  float(rng.uniform(0.2, 0.5)), _seed(rng), limit)
    parts = {
        "body": body,
        "cabin": UpFacing(body, glass),
        "wheel": tyre,
        "hub": hub,
        "headlight": Solid(_jitter(rng, (0.92, 0.92, 0.88), 0.03)),
        "taillight": Solid(_jitter(rng, (0.70, 0.06, 0.05), 0.03)),
    }
    return Material({name: AtScale(p, metres) for name, p in parts.items()}, default=AtScale(body, metres))


def real_material(category: str, rng: np.random.Generator, shape: SyntheticShape | None = None) -> Material:
    """A material a photo of a real ``category`` ('chair' or 'car') would show, drawn from ``rng`` only,
    at ``shape``'s physical scale (typical sizes when None), its parts chosen for the shape's family."""
    if category == "chair":
        return real_chair_material(rng, shape)
    if category == "car":
        return real_car_material(rng, shape)
    raise ValueError(f"unknown category {category!r}")


__all__ = [
    "AtScale", "BrushedMetal", "DarkGlass", "Fabric", "Grain", "LIMIT_PER_UNIT", "Leather", "Painted", "Rubber", "Seams",
    "banded_noise", "fade", "metres_per_unit", "real_material",
]
