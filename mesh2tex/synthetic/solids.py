"""Labelled solids: the parts procedural shapes are built of, and the builder that unions them.

Each solid is a closed manifold3d ``Manifold`` (rounded slabs, boxes, tapered cylinders and bars,
convex hulls of extruded side profiles); :class:`PartBuilder` unions them and keeps each output
triangle's part label (:data:`PART_NAMES`). Units are the caller's (metres before normalisation).
"""

from __future__ import annotations

import math

import manifold3d as mf
import numpy as np

# One integer id per part name for every category, so face labels mean the same everywhere.
PART_NAMES: tuple[str, ...] = (
    "seat",
    "back",
    "leg",
    "arm",
    "base",  # chairs
    "body",
    "cabin",
    "wheel",
    "hub",
    "headlight",
    "taillight",  # cars
)
PART_ID: dict[str, int] = {name: index for index, name in enumerate(PART_NAMES)}


class PartBuilder:
    """Collects labelled solids and unions them, keeping each output triangle's part label."""

    def __init__(self):
        self.solids: list[tuple[mf.Manifold, int]] = []
        self.cuts: list[mf.Manifold] = []

    def add(self, part: str, solid: mf.Manifold) -> None:
        self.solids.append((solid, PART_ID[part]))

    def cut(self, solid: mf.Manifold) -> None:
        """Subtract ``solid`` from everything added so far (and from what is added later)."""
        self.cuts.append(solid)

    def union(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        originals = [solid.as_original() for solid, _ in self.solids]
        label_of = {m.original_id(): part for m, (_, part) in zip(originals, self.solids)}
        result = mf.Manifold.batch_boolean(originals, mf.OpType.Add)
        if self.cuts:
            result = result - mf.Manifold.batch_boolean(self.cuts, mf.OpType.Add)
        # Nearly coincident faces of two parts leave slivers; collapsing edges under 0.5 mm removes
        # them (a mesh file rounding its coordinates would otherwise pinch them shut).
        result = result.simplify(5e-4)
        mesh = result.to_mesh()
        vertices = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3]
        faces = np.asarray(mesh.tri_verts, dtype=np.int64)
        run_index = np.asarray(mesh.run_index) // 3  # triangle ranges of each input solid
        face_parts = np.empty(len(faces), dtype=np.int64)
        for k, original in enumerate(mesh.run_original_id):
            # A cutter's faces become the walls of the hole: they take the label of the nearest part
            # below, which the caller arranges by cutting only the body.
            face_parts[run_index[k] : run_index[k + 1]] = label_of.get(original, PART_ID["body"])
        # Only positions are stored, so manifold3d shares every vertex: the mesh is closed as is.
        used = np.unique(faces)
        remap = np.full(len(vertices), -1, dtype=np.int64)
        remap[used] = np.arange(len(used))
        vertices, faces = vertices[used], remap[faces]
        order = np.argsort(face_parts, kind="stable")
        return vertices, faces[order], face_parts[order]


def place(solid: mf.Manifold, rotation: np.ndarray, offset) -> mf.Manifold:
    """Apply x -> rotation @ x + offset (rotation a proper 3x3 rotation)."""
    matrix = np.hstack([np.asarray(rotation, dtype=np.float64), np.asarray(offset, dtype=np.float64)[:, None]])
    return solid.transform(matrix)


# Extrusions run along +z; these rotations send the extrusion axis elsewhere.
Z_TO_Y = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # cross-section (x, y) -> world (x, -z); extrude along +y
Z_TO_X = np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]])  # cross-section (x, y) -> world (-z, y); extrude along +x


def rounded_rect(width: float, height: float, radius: float, segments: int = 24) -> mf.CrossSection:
    radius = min(radius, 0.49 * min(width, height))
    if radius <= 1e-4:
        return mf.CrossSection.square((width, height), True)
    inner = mf.CrossSection.square((width - 2 * radius, height - 2 * radius), True)
    return inner.offset(radius, mf.JoinType.Round, circular_segments=segments)


def box(size, centre) -> mf.Manifold:
    """Axis-aligned box of ``size`` (x, y, z) centred at ``centre``."""
    return mf.Manifold.cube(tuple(float(s) for s in size), True).translate(tuple(float(c) for c in centre))


def slab(width: float, depth: float, thickness: float, radius: float, centre) -> mf.Manifold:
    """A horizontal plate (x width, z depth, y thickness) with rounded vertical edges."""
    solid = mf.Manifold.extrude(rounded_rect(width, depth, radius), thickness)
    return place(solid, Z_TO_Y, np.asarray(centre, dtype=np.float64) - [0, thickness / 2, 0])


def panel(width: float, height: float, thickness: float, radius: float) -> mf.Manifold:
    """An upright plate in the x-y plane, bottom edge centred at the origin, thickness along z."""
    solid = mf.Manifold.extrude(rounded_rect(width, height, radius), thickness)
    return solid.translate((0.0, height / 2, -thickness / 2))


def rod(
    start, end, radius_start: float, radius_end: float | None = None, segments: int = 16, square: bool = False
) -> mf.Manifold:
    """A (tapered) cylinder, or a square bar when ``square``, from ``start`` to ``end``."""
    start, end = np.asarray(start, dtype=np.float64), np.asarray(end, dtype=np.float64)
    axis = end - start
    length = float(np.linalg.norm(axis))
    radius_end = radius_start if radius_end is None else radius_end
    if square:
        solid = mf.Manifold.extrude(
            mf.CrossSection.square((2 * radius_start, 2 * radius_start), True),
            length,
            scale_top=(radius_end / radius_start, radius_end / radius_start),
        )
    else:
        solid = mf.Manifold.cylinder(length, radius_start, radius_end, segments)
    return place(solid, rotation_from_z(axis / length), start)


def rotation_from_z(direction: np.ndarray) -> np.ndarray:
    """A rotation matrix that maps +z onto the unit vector ``direction``."""
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(z, direction)
    c = float(np.dot(z, direction))
    if np.linalg.norm(v) < 1e-9:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1 + c)


def rotation_x(degrees: float) -> np.ndarray:
    a = math.radians(degrees)
    return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])


def rotation_y(degrees: float) -> np.ndarray:
    a = math.radians(degrees)
    return np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])


def hull(points) -> mf.Manifold:
    return mf.Manifold.hull_points(np.asarray(points, dtype=np.float64))


def prism_hull(profile_zy: np.ndarray, half_width: float, bevel: float) -> mf.Manifold:
    """Convex solid from a side profile (K, 2) of (z, y) points, across x in [-half_width, half_width].

    The edges are chamfered by ``bevel``: the full profile spans the narrower width and a profile
    shrunk towards its centroid by ``bevel`` spans the full width.
    """
    centre = profile_zy.mean(axis=0)
    shrink = centre + (profile_zy - centre) * (1 - bevel / np.maximum(np.abs(profile_zy - centre).max(), 1e-9))
    points = []
    for zy, half in ((profile_zy, half_width - bevel), (shrink, half_width)):
        for sign in (-1.0, 1.0):
            points.extend((sign * half, y, z) for z, y in zy)
    return hull(points)
