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

import numpy as np

from mesh2tex.synthetic.materials import (
    GLASS,
    LEATHER,
    METAL,
    PAINT,
    Colour,
    Material,
    Pattern,
    Solid,
    UpFacing,
    _jitter,
    _pick,
)
from mesh2tex.synthetic.physical_patterns import (
    RUBBER,
    AtScale,
    BrushedMetal,
    DarkGlass,
    Fabric,
    Grain,
    Leather,
    Painted,
    Rubber,
    Seams,
    banded_noise,
    fade,
)
from mesh2tex.synthetic.shapes import SyntheticShape
from mesh2tex.synthetic.solids import PART_ID

# cycles per object diagonal the world's renders resolve (256 px renders span ~200 px per diagonal)
LIMIT_PER_UNIT = 64.0
TYPICAL_METRES = {"chair": 1.2, "car": 5.0}  # a bounding-box diagonal when the shape is not known

# Palettes (sRGB in [0, 1]). Wood: (light, dark) pairs of oak, walnut, beech/birch, cherry, ash, stained black.
WOODS = (
    ((0.74, 0.56, 0.36), (0.52, 0.36, 0.20)),
    ((0.42, 0.28, 0.18), (0.24, 0.15, 0.09)),
    ((0.86, 0.72, 0.54), (0.70, 0.55, 0.38)),
    ((0.66, 0.38, 0.24), (0.45, 0.23, 0.13)),
    ((0.84, 0.76, 0.62), (0.62, 0.52, 0.40)),
    ((0.16, 0.14, 0.13), (0.08, 0.07, 0.07)),
)
# Upholstery fabrics: greys, navy, bottle green, mustard, rust, oatmeal, charcoal, teal, burgundy, sand.
FABRICS = (
    (0.55, 0.55, 0.56),
    (0.16, 0.22, 0.38),
    (0.18, 0.33, 0.24),
    (0.74, 0.58, 0.22),
    (0.62, 0.30, 0.18),
    (0.78, 0.73, 0.64),
    (0.22, 0.22, 0.24),
    (0.16, 0.40, 0.42),
    (0.42, 0.10, 0.14),
    (0.70, 0.62, 0.48),
)
PLASTICS = (
    (0.93, 0.93, 0.91),
    (0.10, 0.10, 0.10),
    (0.80, 0.22, 0.16),
    (0.92, 0.74, 0.16),
    (0.22, 0.44, 0.72),
    (0.55, 0.66, 0.58),
    (0.85, 0.60, 0.55),
)


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
    return Grain(
        _jitter(rng, light, 0.03),
        _jitter(rng, dark, 0.02),
        _axis(rng, axis),
        float(rng.uniform(8, 25)),
        float(rng.uniform(1, 4)),
        float(rng.uniform(150, 400)),
        _seed(rng),
        limit,
    )


def fabric(rng: np.random.Generator, limit: float) -> Fabric:
    return Fabric(
        _jitter(rng, _pick(rng, FABRICS), 0.04),
        float(rng.uniform(400, 1000)),
        float(rng.uniform(0.2, 0.45)),
        float(rng.uniform(0.04, 0.14)),
        float(rng.uniform(80, 250)),
        float(rng.uniform(4, 12)),
        _seed(rng),
        limit,
    )


def leather(rng: np.random.Generator, limit: float) -> Leather:
    return Leather(
        _jitter(rng, _pick(rng, LEATHER), 0.03),
        float(rng.uniform(300, 800)),
        float(rng.uniform(0.06, 0.16)),
        float(rng.uniform(6, 20)),
        float(rng.uniform(0.06, 0.16)),
        float(rng.uniform(2, 6)),
        _seed(rng),
        limit,
    )


def metal(rng: np.random.Generator, limit: float, axis: int = 1) -> Pattern:
    """Brushed steel or aluminium, or painted metal (black, white or a colour), half and half."""
    if rng.random() < 0.5:
        return BrushedMetal(
            _jitter(rng, _pick(rng, METAL[:2] + METAL[3:]), 0.03),
            _axis(rng, axis),
            float(rng.uniform(800, 2500)),
            float(rng.uniform(1, 5)),
            float(rng.uniform(0.05, 0.15)),
            float(rng.uniform(3, 10)),
            _seed(rng),
            limit,
        )
    return painted(rng, limit, _pick(rng, ((0.10, 0.10, 0.11), (0.90, 0.90, 0.88)) + PAINT[:4]))


def painted(rng: np.random.Generator, limit: float, colour: Colour) -> Painted:
    return Painted(
        _jitter(rng, colour, 0.03),
        float(rng.uniform(200, 600)),
        float(rng.uniform(0.01, 0.04)),
        float(rng.uniform(1, 5)),
        float(rng.uniform(0.02, 0.08)),
        _seed(rng),
        limit,
    )


def plastic(rng: np.random.Generator, limit: float) -> Painted:
    """Moulded plastic: a colour of PLASTICS with a fine stipple and a slight variation of its finish."""
    return painted(rng, limit, _pick(rng, PLASTICS))


def cover(rng: np.random.Generator, limit: float, seams: bool) -> Pattern:
    """A seat or back cover: fabric (60 %) or leather, sewn in panels (and channels, a third of the time) when
    ``seams``."""
    cloth = fabric(rng, limit) if rng.random() < 0.6 else leather(rng, limit)
    if not seams:
        return cloth
    channels = float(rng.uniform(0.08, 0.16)) if rng.random() < 1 / 3 else 0.0
    return Seams(
        cloth,
        float(rng.uniform(0.15, 0.45)),
        channels,
        float(rng.uniform(0.004, 0.008)),
        float(rng.uniform(0.3, 0.55)),
        limit,
    )


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
            seat = (
                wood(rng, limit, 2, species) if isinstance(frame, Grain) or rng.random() < 0.5 else plastic(rng, limit)
            )
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
    tyre = Rubber(
        _jitter(rng, RUBBER, 0.01),
        float(rng.uniform(0.025, 0.045)),
        float(rng.uniform(0.005, 0.012)),
        float(rng.uniform(0.2, 0.5)),
        _seed(rng),
        limit,
    )
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
    "AtScale",
    "BrushedMetal",
    "DarkGlass",
    "Fabric",
    "Grain",
    "LIMIT_PER_UNIT",
    "Leather",
    "Painted",
    "Rubber",
    "Seams",
    "banded_noise",
    "fade",
    "metres_per_unit",
    "real_material",
]
