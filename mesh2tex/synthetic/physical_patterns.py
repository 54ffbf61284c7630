"""Patterns at a physical scale, band-limited to what a render resolves (the varied world's materials).

Wood grain, fabric weave, leather, seams, brushed and painted metal, tyre rubber and dark glass, each a
:class:`~mesh2tex.synthetic.materials.Pattern` whose parameters are physical: frequencies in cycles
per metre on the object, widths in metres; :class:`AtScale` evaluates one at ``points * metres``.
Every pattern takes ``limit``, the finest frequency it may show, and fades each component from full
contrast at ``limit / 2`` to its mean at ``limit`` (:func:`fade`); why, and how the varied world
chooses and scales them: :mod:`mesh2tex.synthetic.real_materials`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mesh2tex.synthetic.materials import (
    Colour,
    Pattern,
    _c,
    _mix,
    _permutation,
    _value_noise,
    triplanar,
)

RUBBER = (0.16, 0.16, 0.17)  # tyre rubber, sRGB
WEAVE_MEAN = 0.7043  # the mean of |sin(pi x)|^0.7, the weave's brightness


def fade(frequency: float, limit: float) -> float:
    """Contrast kept by a component of ``frequency`` (cycles per metre) under the band ``limit``: 1 up to
    ``limit / 2``, falling linearly to 0 at ``limit`` (``limit`` inf: 1)."""
    if not math.isfinite(limit):
        return 1.0
    return float(np.clip(2.0 - 2.0 * frequency / limit, 0.0, 1.0))


def banded_noise(
    coords: np.ndarray, frequency: float, octaves: int, seed: int, limit: float, gain: float = 0.5
) -> np.ndarray:
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


def grain_frame(axis) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A unit ``axis`` and two unit vectors perpendicular to it and to each other."""
    a = _c(axis) / np.linalg.norm(axis)
    other = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    b = np.cross(a, other)
    b /= np.linalg.norm(b)
    return a, b, np.cross(a, b)


def soft_line(distance: np.ndarray, width: float, limit: float) -> np.ndarray:
    """A line's profile (N,) in [0, 1] at ``distance`` metres from its centre: a Gaussian of ``width``,
    widened to the band limit with its integral kept (a seam finer than a pixel darkens it a little)."""
    resolved = 1.0 / limit if math.isfinite(limit) else 0.0
    drawn = max(width, resolved)
    return (width / drawn) * np.exp(-0.5 * (distance / (0.4 * drawn)) ** 2)


class MetricPattern(Pattern):
    """A pattern in metres: describes its floats rounded to 4 significant figures (small widths survive)."""

    def describe(self) -> dict:
        out = super().describe()
        for key, value in list(out.items()):
            if isinstance(value, float):
                out[key] = float(f"{getattr(self, key):.4g}") if math.isfinite(getattr(self, key)) else "inf"
        return out


@dataclass
class Grain(MetricPattern):
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
        a, b, c = grain_frame(self.axis)
        u, v, w = points @ a, points @ b, points @ c
        streaks = banded_noise(
            np.stack([u * self.along, v * self.across, w * self.across], axis=1), self.across, 3, self.seed, self.limit
        )
        phase = (v + 0.6 * w) * self.rings + 6.0 * streaks
        ring = (0.5 + 0.5 * np.cos(2 * np.pi * phase)) ** 4  # thin dark latewood lines
        t = 0.5 + 3.0 * (streaks - 0.5) + 0.35 * fade(self.rings, self.limit) * (ring - 0.2)
        return _mix(self.light, self.dark, t)


@dataclass
class Fabric(MetricPattern):
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
        weave = triplanar(self.weave, points, normals) if keep > 0 else np.full(len(points), WEAVE_MEAN)
        brightness = 1.0 - self.weave_contrast * (
            1.0 - (WEAVE_MEAN + keep * (weave - WEAVE_MEAN))
        )  # the faded weave keeps its mean
        yarn = banded_noise(points * self.yarn, self.yarn, 2, self.seed, self.limit)
        nap = banded_noise(points * self.nap, self.nap, 2, self.seed + 1, self.limit)
        brightness = brightness * (1.0 + self.heather * 2.0 * (yarn - 0.5)) * (1.0 + 0.3 * (nap - 0.5))
        return np.clip(_c(self.colour)[None] * brightness[:, None], 0.0, 1.0)


@dataclass
class Leather(MetricPattern):
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
        crease = banded_noise(
            points * self.creases * np.array([1.0, 3.0, 1.0]), self.creases * 3.0, 2, self.seed + 2, self.limit
        )
        brightness = (1.0 + self.pebble_contrast * 2.0 * (pebble - 0.5)) * (
            1.0 + self.mottle_contrast * 2.0 * (mottle - 0.5)
        )
        brightness *= 1.0 - 0.15 * np.clip((crease - 0.55) * 4.0, 0.0, 1.0)
        return np.clip(_c(self.colour)[None] * brightness[:, None], 0.0, 1.0)


@dataclass
class Seams(MetricPattern):
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
                dark = np.maximum(dark, soft_line(distance, self.width, self.limit))
                roll = soft_line(distance - 2.0 * self.width, 2.5 * self.width, self.limit)
                dark -= 0.25 * roll
        return np.clip(out * (1.0 - self.depth * dark)[:, None], 0.0, 1.0)

    def describe(self):
        out = super().describe()
        out["cover"] = self.cover.describe()
        return out


@dataclass
class BrushedMetal(MetricPattern):
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
        a, b, c = grain_frame(self.axis)
        u, v, w = points @ a, points @ b, points @ c
        streak = banded_noise(
            np.stack([u * self.along, v * self.across, w * self.across], axis=1), self.across, 2, self.seed, self.limit
        )
        sheen = banded_noise(points * self.sheen, self.sheen, 2, self.seed + 1, self.limit)
        brightness = (1.0 + self.streak_contrast * 2.0 * (streak - 0.5)) * (1.0 + 0.16 * (sheen - 0.5))
        return np.clip(_c(self.colour)[None] * brightness[:, None], 0.0, 1.0)


@dataclass
class Painted(MetricPattern):
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
        brightness = (1.0 + self.peel_contrast * 2.0 * (peel - 0.5)) * (
            1.0 + self.finish_contrast * 2.0 * (finish - 0.5)
        )
        return np.clip(_c(self.colour)[None] * brightness[:, None], 0.0, 1.0)


@dataclass
class Rubber(MetricPattern):
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
        groove = soft_line(np.abs(offset), self.groove_width, self.limit)
        wear = banded_noise(points * 20.0, 20.0, 2, self.seed, self.limit)
        brightness = (1.0 - 0.5 * groove * (1 - side)) * (1.0 + self.sidewall_lift * side) * (1.0 + 0.2 * (wear - 0.5))
        return np.clip(_c(self.colour)[None] * brightness[:, None], 0.0, 1.0)


@dataclass
class DarkGlass(MetricPattern):
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
