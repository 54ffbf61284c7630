"""Which world a shape comes from: today's boxy one, or the varied one of real furniture and car families.

``boxy`` is :func:`mesh2tex.synthetic.shapes.generate_shape`, unchanged (the shipped models were
trained on it). ``real`` first draws a family by its share (:data:`FAMILIES`), then the family's
design, both from the shape's own random stream, so a shape does not depend on the others.
"""

from __future__ import annotations

import numpy as np

from mesh2tex.synthetic.car_families import CAR_FAMILIES
from mesh2tex.synthetic.chair_families import CHAIR_FAMILIES
from mesh2tex.synthetic.shapes import SyntheticShape, generate_shape, shape_from_design

VARIETIES: tuple[str, ...] = ("boxy", "real")
# category -> family name -> (design function, share, parts every shape of the family has)
FAMILIES: dict[str, dict[str, tuple]] = {"chair": CHAIR_FAMILIES, "car": CAR_FAMILIES}


def family_shares(category: str) -> dict[str, float]:
    """{family: share of the varied world's shapes of ``category``} (the shares sum to 1)."""
    return {name: share for name, (_, share, _) in FAMILIES[category].items()}


def generate_varied_shape(
    category: str, rng: np.random.Generator, variety: str = "boxy", family: str | None = None
) -> SyntheticShape:
    """One random shape of ``category`` from the ``variety`` world, drawn from ``rng`` only.

    ``family`` (varied world only) fixes the family instead of drawing it; the design is still drawn
    from ``rng``. The shape's ``params`` name its ``family``.
    """
    if variety not in VARIETIES:
        raise ValueError(f"unknown variety {variety!r}; choose one of {', '.join(VARIETIES)}")
    if variety == "boxy":
        if family is not None:
            raise ValueError("the boxy world has no families")
        return generate_shape(category, rng)
    if category not in FAMILIES:
        raise ValueError(f"unknown category {category!r}; choose one of {', '.join(FAMILIES)}")
    names = list(FAMILIES[category])
    drawn = names[int(rng.choice(len(names), p=np.array(list(family_shares(category).values()))))]
    name = drawn if family is None else family
    if name not in FAMILIES[category]:
        raise ValueError(f"unknown {category} family {name!r}; choose one of {', '.join(names)}")
    return shape_from_design(category, FAMILIES[category][name][0], rng, repair=collapse_short_edges)


SHORT_EDGE = 2e-5  # share of the bounding-box diagonal: unions of many curved parts leave a few edges this short


def collapse_short_edges(vertices: np.ndarray, faces: np.ndarray, face_parts: np.ndarray, share: float = SHORT_EDGE):
    """Merge the two ends of every edge shorter than ``share`` of the bounding-box diagonal (the
    triangles that collapse go). Twice the world's ``MIN_EDGE``, so a repaired shape passes its check.

    Returns (vertices, faces, face_parts) with unused vertices dropped, or None when the result is not
    a closed two-manifold any more (every edge in exactly two triangles, once in each direction).
    """
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    length = share * np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0))
    short = edges[np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1) < length]
    if len(short) == 0:
        return vertices, faces, face_parts
    target = np.arange(len(vertices))

    def root(i):
        while target[i] != i:
            i = target[i]
        return i

    for a, b in short:
        ra, rb = root(a), root(b)
        if ra != rb:
            target[max(ra, rb)] = min(ra, rb)
    merged = np.array([root(i) for i in range(len(vertices))])[faces]
    keep = (merged[:, 0] != merged[:, 1]) & (merged[:, 1] != merged[:, 2]) & (merged[:, 2] != merged[:, 0])
    faces, face_parts = merged[keep], face_parts[keep]
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    if len(np.unique(directed, axis=0)) != len(directed) or len(
        np.unique(np.sort(directed, axis=1), axis=0)
    ) * 2 != len(directed):
        return None
    used = np.unique(faces)
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[faces], face_parts
