"""The chair families of the varied world (``prepare synthetic --variety real``).

Each family is a design function ``(builder, rng) -> params`` for
:func:`mesh2tex.synthetic.shapes.shape_from_design`: it adds labelled solids (seat, back, leg, arm, base)
in metres, y up, the front towards +z, the floor at y = 0, and returns its design choices with a
``family`` key. Proportions are drawn from the catalogue ranges of ``docs/synthetic.md`` ("The varied
world"): seat heights 42-48 cm for dining and shell chairs, 40-53 cm for office chairs, and so on.
Curved parts are lofts from :mod:`mesh2tex.synthetic.sweeps`: tubes along Bezier curves and arcs,
backs bent around the sitter, shells that turn from seat into back, stuffed cushions.
"""

from __future__ import annotations

from typing import Any

from mesh2tex.synthetic.chair_frames import bench, folding, four_legged, rocking
from mesh2tex.synthetic.chair_seats import armchair, office, shell, sofa, stool
from mesh2tex.synthetic.shapes import _chair


def _classic(builder, rng) -> dict[str, Any]:
    """Today's boxy chairs (``mesh2tex.synthetic.shapes``), kept as one family among the others."""
    return {"family": "classic", **_chair(builder, rng)}


# family name -> (design function, share of the varied world's chairs, parts it always has)
CHAIR_FAMILIES: dict[str, tuple] = {
    "four_legged": (four_legged, 0.18, ("seat", "back", "leg")),
    "office": (office, 0.14, ("seat", "back", "leg", "base")),
    "armchair": (armchair, 0.12, ("seat", "back", "arm")),
    "sofa": (sofa, 0.10, ("seat", "back", "arm")),
    "stool": (stool, 0.10, ("seat", "leg")),
    "bench": (bench, 0.07, ("seat", "leg")),
    "rocking": (rocking, 0.07, ("seat", "back", "leg")),
    "folding": (folding, 0.07, ("seat", "back", "leg")),
    "shell": (shell, 0.07, ("seat", "back", "leg")),
    "classic": (_classic, 0.08, ("seat", "back", "leg")),
}
