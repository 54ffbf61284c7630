"""Texture exemplars (flat texture photos) made from the world's procedural patterns.

The cellular automaton learns a texture from one exemplar image. Tests, benchmarks and the demo need
exemplars without downloads; these are the world's patterns (:mod:`mesh2tex.synthetic.materials`)
evaluated on a flat square, as a texture photo would show them, and two regular patterns with
structure of their own (running-bond bricks, a lattice of dots), solid in 3D through a triplanar
projection so that the same pattern can be painted on any mesh as an oracle. ``brick``, ``grass``
and ``gravel`` are scikit-image's photographs, tinted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mesh2tex.synthetic.materials import (
    Checker,
    Colour,
    Noise,
    Pattern,
    PhotoPattern,
    Stripes,
    Weave,
    WoodGrain,
    _mix,
    triplanar,
)


@dataclass
class Bricks(Pattern):
    """Running-bond brickwork: rows ``height`` apart, bricks ``width`` long, every other row shifted
    by half a brick, ``mortar`` wide joints; triplanar on a mesh."""

    brick: Colour
    joint: Colour
    width: float
    height: float
    mortar: float

    def __call__(self, points, normals):
        def joint(u, v):
            row = np.floor(v / self.height)
            along = np.mod(u / self.width + 0.5 * np.mod(row, 2), 1.0) * self.width
            across = np.mod(v, self.height)
            half = self.mortar / 2
            return (
                (along < half) | (along > self.width - half) | (across < half) | (across > self.height - half)
            ).astype(np.float64)

        return _mix(self.brick, self.joint, triplanar(joint, points, normals))


@dataclass
class Dots(Pattern):
    """Discs of ``radius`` on a hexagonal lattice of ``spacing`` (rows spacing * sqrt(3) / 2 apart),
    ``dot`` on ``ground``; triplanar on a mesh."""

    dot: Colour
    ground: Colour
    spacing: float
    radius: float

    def __call__(self, points, normals):
        def disc(u, v):
            pitch = self.spacing * np.sqrt(3) / 2
            row = np.round(v / pitch)
            shift = 0.5 * self.spacing * np.mod(row, 2)
            du = np.mod(u - shift + 0.5 * self.spacing, self.spacing) - 0.5 * self.spacing
            dv = v - row * pitch
            return (du**2 + dv**2 <= self.radius**2).astype(np.float64)

        return _mix(self.ground, self.dot, triplanar(disc, points, normals))


# name -> pattern on the unit square (coordinates in [0, 1]^2, z = 0)
EXEMPLARS: dict[str, Pattern] = {
    "stripes": Stripes((0.85, 0.20, 0.15), (0.95, 0.88, 0.70), (0.7071, 0.7071, 0.0), frequency=9.0, duty=0.45),
    "checker": Checker((0.12, 0.20, 0.45), (0.90, 0.85, 0.30), size=0.125),
    "weave": Weave((0.20, 0.42, 0.30), (0.85, 0.80, 0.62), frequency=14.0),
    "wood": WoodGrain((0.80, 0.60, 0.38), (0.45, 0.27, 0.12), (0.0, 1.0, 0.0), rings=14.0, seed=3),
    "camouflage": Noise((0.30, 0.36, 0.18), (0.62, 0.55, 0.35), scale=7.0, octaves=3, seed=5, threshold=0.5),
    "brick": PhotoPattern("brick", (0.35, 0.12, 0.08), (0.92, 0.62, 0.45), tile=1.0),
    "bricks": Bricks((0.66, 0.24, 0.16), (0.86, 0.83, 0.76), width=0.25, height=0.125, mortar=0.025),
    "dots": Dots((0.15, 0.22, 0.50), (0.95, 0.92, 0.80), spacing=0.1428, radius=0.04),
    "grass": PhotoPattern(
        "grass", (0.10, 0.22, 0.05), (0.62, 0.78, 0.35), tile=2.0
    ),  # extent 1: a 2x crop of the photo
    "gravel": PhotoPattern("gravel", (0.25, 0.23, 0.21), (0.85, 0.82, 0.76), tile=2.0),
}


def exemplar_image(name: str, size: int = 128, extent: float = 1.0) -> np.ndarray:
    """(size, size, 3) uint8 image of the exemplar ``name`` (one of :data:`EXEMPLARS`) over the square
    [0, extent]^2 of its pattern (extent 0.5: a 2x close-up, each feature twice as many pixels)."""
    if name not in EXEMPLARS:
        raise ValueError(f"unknown exemplar {name!r}; expected one of {sorted(EXEMPLARS)}")
    t = (np.arange(size) + 0.5) / size * extent
    u, v = np.meshgrid(t, t, indexing="xy")
    points = np.stack([u.ravel(), 1.0 - v.ravel(), np.zeros(size * size)], axis=1)
    normals = np.broadcast_to(np.array([0.0, 0.0, 1.0]), points.shape)
    rgb = EXEMPLARS[name](points, normals).reshape(size, size, 3)
    return (np.clip(rgb, 0, 1) * 255 + 0.5).astype(np.uint8)
