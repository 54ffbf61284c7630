"""Hand-modelled chairs and cars, made apart from the synthetic world's code, as a yardstick for its geometry.

These meshes are **not** from any collection and **not** from ``mesh2tex.synthetic``: each is put
together by hand from trimesh's primitives (boxes, cylinders, capsules, spheres, tori, convex hulls),
the way a quick modeller would block out a catalogue object, and they were written once, without
looking at the world's statistics (nothing here is tuned to match a table). The parts overlap rather
than being joined (like many meshes in real collections); ``prepare shapes`` cleans and remeshes them.
Units are metres, y up, the front towards +z.

    from benchmarks.world_reference_shapes import reference_shapes
    shapes = reference_shapes("chair")   # [(name, trimesh.Trimesh), ...]
"""

from __future__ import annotations

import numpy as np
import trimesh
from trimesh.creation import box, capsule, cylinder, icosphere, torus


def _at(mesh: trimesh.Trimesh, x: float, y: float, z: float) -> trimesh.Trimesh:
    mesh.apply_translation((x, y, z))
    return mesh


def _bar(a, b, radius: float, sections: int = 16) -> trimesh.Trimesh:
    """A cylinder from point a to point b."""
    return cylinder(radius=radius, segment=np.array([a, b], dtype=float), sections=sections)


def _ellipsoid(size, centre) -> trimesh.Trimesh:
    mesh = icosphere(subdivisions=3)
    mesh.apply_scale(np.asarray(size, dtype=float) / 2)
    return _at(mesh, *centre)


def _rotated_box(size, centre, degrees_about_x: float) -> trimesh.Trimesh:
    mesh = box(extents=size)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.radians(degrees_about_x), (1, 0, 0)))
    return _at(mesh, *centre)


def _windsor_chair() -> list[trimesh.Trimesh]:
    parts = [_ellipsoid((0.46, 0.05, 0.42), (0, 0.44, 0))]
    for x in (-0.17, 0.17):
        for z in (-0.15, 0.15):
            parts.append(_bar((x * 1.25, 0, z * 1.25), (x, 0.44, z), 0.018))
    hoop = torus(major_radius=0.2, minor_radius=0.014)
    hoop.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
    parts.append(_at(hoop, 0, 0.68, -0.2))
    parts += [_bar((x, 0.45, -0.19), (x, 0.86, -0.21), 0.008) for x in np.linspace(-0.12, 0.12, 5)]
    return parts


def _club_armchair() -> list[trimesh.Trimesh]:
    parts = [_at(box(extents=(0.86, 0.3, 0.84)), 0, 0.2, 0)]
    parts.append(_ellipsoid((0.6, 0.16, 0.66), (0, 0.4, 0.06)))  # seat cushion
    parts.append(_rotated_box((0.62, 0.45, 0.2), (0, 0.58, -0.33), -10))  # back
    for x in (-0.34, 0.34):
        parts.append(_at(box(extents=(0.18, 0.38, 0.84)), x, 0.3, 0))
        parts.append(
            capsule(height=0.7, radius=0.1, count=(16, 16))
            .apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
            .apply_translation((x, 0.55, 0))
        )
    parts += [_bar((x, 0, z), (x, 0.06, z), 0.025) for x in (-0.38, 0.38) for z in (-0.36, 0.36)]
    return parts


def _office_chair() -> list[trimesh.Trimesh]:
    parts = [_bar((0, 0.08, 0), (0, 0.42, 0), 0.025), _bar((0, 0.06, 0), (0, 0.12, 0), 0.05)]
    for k in range(5):
        a = 2 * np.pi * k / 5
        tip = np.array([0.32 * np.sin(a), 0.07, 0.32 * np.cos(a)])
        parts.append(_bar((0, 0.09, 0), tip, 0.02, 8))
        parts.append(_at(icosphere(subdivisions=2, radius=0.03), tip[0], 0.03, tip[2]))
    parts.append(_ellipsoid((0.5, 0.1, 0.48), (0, 0.46, 0)))
    parts.append(_rotated_box((0.46, 0.55, 0.06), (0, 0.8, -0.26), -12))
    parts.append(_bar((0, 0.44, -0.1), (0, 0.62, -0.27), 0.02))
    for x in (-0.27, 0.27):
        parts.append(_bar((x * 0.6, 0.44, 0), (x, 0.66, 0), 0.015))
        parts.append(_at(box(extents=(0.07, 0.03, 0.24)), x, 0.67, 0.02))
    return parts


def _bar_stool() -> list[trimesh.Trimesh]:
    parts = [_bar((0, 0.7, 0), (0, 0.75, 0), 0.19, 32)]
    parts += [
        _bar((0.22 * np.sin(a), 0, 0.22 * np.cos(a)), (0.13 * np.sin(a), 0.71, 0.13 * np.cos(a)), 0.016)
        for a in np.linspace(0, 2 * np.pi, 4, endpoint=False) + np.pi / 4
    ]
    ring = torus(major_radius=0.19, minor_radius=0.01)
    ring.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
    parts.append(_at(ring, 0, 0.25, 0))
    return parts


def _sofa() -> list[trimesh.Trimesh]:
    parts = [_at(box(extents=(2.0, 0.25, 0.9)), 0, 0.2, 0), _rotated_box((1.7, 0.5, 0.22), (0, 0.6, -0.33), -8)]
    parts += [_ellipsoid((0.58, 0.16, 0.66), (x, 0.38, 0.08)) for x in (-0.57, 0.0, 0.57)]
    parts += [_at(box(extents=(0.16, 0.4, 0.9)), x, 0.32, 0) for x in (-0.92, 0.92)]
    parts += [_bar((x, 0, z), (x, 0.09, z), 0.02) for x in (-0.9, 0.9) for z in (-0.38, 0.38)]
    return parts


def _cantilever_chair() -> list[trimesh.Trimesh]:
    parts = []
    for x in (-0.2, 0.2):
        loop = [(x, 0.0, -0.2), (x, 0.0, 0.28), (x, 0.42, 0.22), (x, 0.42, -0.2), (x, 0.86, -0.27)]
        parts += [_bar(a, b, 0.012) for a, b in zip(loop[:-1], loop[1:])]
        parts += [_at(icosphere(subdivisions=2, radius=0.012), *p) for p in loop[1:-1]]
    parts.append(_at(box(extents=(0.44, 0.015, 0.42)), 0, 0.43, 0.02))
    parts.append(_rotated_box((0.42, 0.3, 0.012), (0, 0.7, -0.24), -10))
    return parts


def _wheels(length: float, width: float, radius: float) -> list[trimesh.Trimesh]:
    return [
        _bar((sx * width / 2 - 0.12 * sx, radius, z), (sx * width / 2 + 0.02 * sx, radius, z), radius, 32)
        for sx in (-1, 1)
        for z in (-length * 0.32, length * 0.3)
    ]


def _boxy_sedan() -> list[trimesh.Trimesh]:
    lower = np.array([(x, y, z) for x in (-0.88, 0.88) for y in (0.2, 0.75) for z in (-2.3, 2.3)])
    nose = np.array([(x, 0.55, 2.4) for x in (-0.8, 0.8)])
    cabin = np.array(
        [(x, y, z) for x in (-0.78, 0.78) for y, zs in ((0.75, (-1.3, 1.0)), (1.42, (-0.7, 0.3))) for z in zs]
    )
    return [
        trimesh.convex.convex_hull(np.vstack([lower, nose])),
        trimesh.convex.convex_hull(cabin * (0.97, 1, 1)),
        *_wheels(4.6, 1.8, 0.32),
    ]


def _round_beetle() -> list[trimesh.Trimesh]:
    return [
        _ellipsoid((1.6, 0.8, 4.0), (0, 0.65, 0)),
        _ellipsoid((1.3, 0.9, 2.2), (0, 1.0, -0.2)),
        *_wheels(4.0, 1.6, 0.3),
    ]


def _van() -> list[trimesh.Trimesh]:
    corners = [
        _at(icosphere(subdivisions=2, radius=0.15), x, y, z)
        for x in (-0.85, 0.85)
        for y in (0.35, 1.85)
        for z in (-2.4, 2.2)
    ]
    body = trimesh.convex.convex_hull(
        np.vstack([c.vertices for c in corners] + [np.array([(x, 0.9, 2.55) for x in (-0.8, 0.8)])])
    )
    return [body, *_wheels(5.0, 2.0, 0.33)]


def _suv() -> list[trimesh.Trimesh]:
    lower = _at(box(extents=(1.9, 0.75, 4.6)), 0, 0.65, 0)
    upper = trimesh.convex.convex_hull(
        np.array(
            [(x, y, z) for x in (-0.85, 0.85) for y, zs in ((1.0, (-2.25, 1.1)), (1.75, (-2.15, 0.35))) for z in zs]
        )
    )
    return [lower, upper, *_wheels(4.6, 1.9, 0.37)]


_CHAIRS = {
    "windsor": _windsor_chair,
    "club_armchair": _club_armchair,
    "office": _office_chair,
    "bar_stool": _bar_stool,
    "sofa": _sofa,
    "cantilever": _cantilever_chair,
}
_CARS = {"sedan": _boxy_sedan, "beetle": _round_beetle, "van": _van, "suv": _suv}


def reference_shapes(category: str) -> list[tuple[str, trimesh.Trimesh]]:
    """[(name, mesh)] of the hand-modelled chairs or cars; each mesh is its parts concatenated (overlapping)."""
    makers = _CHAIRS if category == "chair" else _CARS
    return [(name, trimesh.util.concatenate(make())) for name, make in makers.items()]
