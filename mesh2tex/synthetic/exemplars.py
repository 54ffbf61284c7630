"""Texture exemplars (flat texture photos) made from the world's procedural patterns.

The cellular automaton learns a texture from one exemplar image. Tests, benchmarks and the demo need
exemplars without downloads; these are the world's patterns (:mod:`mesh2tex.synthetic.materials`)
evaluated on a flat square, as a texture photo would show them.
"""

from __future__ import annotations

import numpy as np

from mesh2tex.synthetic.materials import Checker, Noise, Pattern, PhotoPattern, Stripes, Weave, WoodGrain

# name -> pattern on the unit square (coordinates in [0, 1]^2, z = 0)
EXEMPLARS: dict[str, Pattern] = {
    "stripes": Stripes((0.85, 0.20, 0.15), (0.95, 0.88, 0.70), (0.7071, 0.7071, 0.0), frequency=9.0, duty=0.45),
    "checker": Checker((0.12, 0.20, 0.45), (0.90, 0.85, 0.30), size=0.125),
    "weave": Weave((0.20, 0.42, 0.30), (0.85, 0.80, 0.62), frequency=14.0),
    "wood": WoodGrain((0.80, 0.60, 0.38), (0.45, 0.27, 0.12), (0.0, 1.0, 0.0), rings=14.0, seed=3),
    "camouflage": Noise((0.30, 0.36, 0.18), (0.62, 0.55, 0.35), scale=7.0, octaves=3, seed=5, threshold=0.5),
    "brick": PhotoPattern("brick", (0.35, 0.12, 0.08), (0.92, 0.62, 0.45), tile=1.0),
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
