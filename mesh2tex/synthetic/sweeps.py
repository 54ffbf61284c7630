"""Curved solids for the varied world: tubes swept along curves, lofts of cross-sections, cushions.

The solids of :mod:`mesh2tex.synthetic.shapes` are boxes, slabs, cylinders and convex hulls. Real
chairs and cars are bent: tubular frames, rocking runners, shells that turn from seat into back,
car bodies whose cross-section changes along the length. Everything here is one construction, the
**loft**: a sequence of closed rings of points (K rings of M points each) joined ring to ring by
quads, closed by a triangulated cap at each end (or joined last ring to first, for a closed loop).

* :func:`tube` sweeps a circle along a polyline with parallel-transport frames (no twist), so a
  tube along a Bezier curve or an arc is a loft of circles.
* :func:`loft` takes the rings as they are: car bodies (rounded rectangles that grow and shrink along
  the length), curved chair backs (arc-shaped bands stacked upwards), shells (dished bands swept along
  the seat-and-back profile).
* :func:`cushion` is a superellipsoid: a box whose edges and corners are rounded like a stuffed pad.

Each returns a closed, outward-oriented ``manifold3d.Manifold`` for ``PartBuilder.add``; units are
metres before normalisation, like the rest of the generators.
"""

from __future__ import annotations

import math

import manifold3d as mf
import numpy as np


def bezier(control, count: int) -> np.ndarray:
    """(C, D) control points -> (count, D) points of the Bezier curve they define, evenly in the parameter."""
    control = np.asarray(control, dtype=np.float64)
    degree = len(control) - 1
    t = np.linspace(0.0, 1.0, count)[:, None]
    weights = [math.comb(degree, k) * t**k * (1 - t) ** (degree - k) for k in range(degree + 1)]
    return sum(w * c for w, c in zip(weights, control))


def arc_points(
    centre, radius: float, start_degrees: float, end_degrees: float, count: int, plane: str = "zy"
) -> np.ndarray:
    """(count, 3) points on a circular arc in the plane named by two axes (first axis at 0 degrees)."""
    axes = {"x": 0, "y": 1, "z": 2}
    a, b = axes[plane[0]], axes[plane[1]]
    angles = np.radians(np.linspace(start_degrees, end_degrees, count))
    points = np.tile(np.asarray(centre, dtype=np.float64), (count, 1))
    points[:, a] += radius * np.cos(angles)
    points[:, b] += radius * np.sin(angles)
    return points


def resample(points, spacing: float) -> np.ndarray:
    """A polyline (N, 3) resampled at about ``spacing`` along its length (ends kept, at least 2 points)."""
    points = np.asarray(points, dtype=np.float64)
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    count = max(2, int(math.ceil(along[-1] / spacing)) + 1)
    targets = np.linspace(0.0, along[-1], count)
    return np.stack([np.interp(targets, along, points[:, d]) for d in range(points.shape[1])], axis=1)


def transport_frames(points: np.ndarray, closed: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tangents, normals and binormals (each (N, 3)) along a polyline by parallel transport (no twist)."""
    if closed:
        tangents = np.roll(points, -1, axis=0) - np.roll(points, 1, axis=0)
    else:
        tangents = np.gradient(points, axis=0)
    tangents /= np.linalg.norm(tangents, axis=1, keepdims=True)
    helper = np.eye(3)[int(np.argmin(np.abs(tangents[0])))]
    normal = np.cross(tangents[0], helper)
    normals = np.empty_like(points)
    for k, t in enumerate(tangents):
        normal = normal - np.dot(normal, t) * t
        normal /= np.linalg.norm(normal)
        normals[k] = normal
    return tangents, normals, np.cross(tangents, normals)


def tube(points, radius, segments: int = 12, closed: bool = False) -> mf.Manifold:
    """A circle of ``radius`` (a number, or one per point for a taper) swept along the polyline ``points`` (N, 3).

    Bends must be gentler than the radius (the rings must not cross); ``closed`` joins the last point
    to the first (a ring-shaped tube, no caps).
    """
    return loft(tube_rings(points, radius, segments, closed), closed=closed)


def tube_rings(points, radius, segments: int = 12, closed: bool = False) -> np.ndarray:
    """The rings (N, segments, 3) of :func:`tube`, for a caller that lofts pieces of them apart (one label each)."""
    points = np.asarray(points, dtype=np.float64)
    radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), (len(points),))
    _, normals, binormals = transport_frames(points, closed)
    # Half a step off the frame's axes: no ring point lies in the plane of a symmetric design's other parts
    # (two meshes with vertices on one plane meet in near-coincident edges, which leave slivers).
    angles = np.linspace(0.0, 2 * math.pi, segments, endpoint=False) + math.pi / segments
    return points[:, None] + radius[:, None, None] * (
        np.cos(angles)[None, :, None] * normals[:, None] + np.sin(angles)[None, :, None] * binormals[:, None]
    )


def loft(rings, closed: bool = False) -> mf.Manifold:
    """The solid bounded by closed rings (K, M, 3), ring k joined to ring k + 1 point by point.

    Each ring must be a simple (not self-crossing) nearly planar polygon; the end rings are closed by
    caps triangulated in their own plane (non-convex end rings are fine). ``closed`` joins the last
    ring to the first instead (a loop, no caps). The orientation is fixed so that the volume is positive.
    Raises ValueError when the rings do not bound a valid solid (e.g. rings that cross each other).
    """
    rings = np.asarray(rings, dtype=np.float64)
    count, size = rings.shape[:2]
    index = np.arange(count * size).reshape(count, size)
    nxt = np.roll(index, -1, axis=1)
    pairs = count if closed else count - 1
    a, b = index[:pairs], nxt[:pairs]
    c, d = np.roll(nxt, -1, axis=0)[:pairs], np.roll(index, -1, axis=0)[:pairs]
    faces = [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]
    if not closed:  # the caps run along the ring at the far end and against it at the near end, like the sides
        faces += [_cap(rings[0])[:, ::-1] + index[0, 0], _cap(rings[-1]) + index[-1, 0]]
    faces = np.concatenate(faces)
    vertices = rings.reshape(-1, 3)
    if _signed_volume(vertices, faces) < 0:
        faces = faces[:, ::-1]
    solid = mf.Manifold(
        mf.Mesh64(
            vert_properties=np.ascontiguousarray(vertices), tri_verts=np.ascontiguousarray(faces, dtype=np.uint64)
        )
    )
    if solid.status() != mf.Error.NoError or solid.volume() <= 0:
        raise ValueError(f"the lofted rings do not bound a valid solid ({solid.status()})")
    return solid


def _cap(ring: np.ndarray) -> np.ndarray:
    """Triangles (T, 3) of ring positions closing the planar ring, each edge of the ring run in the ring's order."""
    centred = ring - ring.mean(axis=0)
    axes = np.linalg.svd(centred, full_matrices=False)[2][:2]  # the ring's plane
    flat = centred @ axes.T
    if np.sum(flat[:, 0] * np.roll(flat[:, 1], -1) - np.roll(flat[:, 0], -1) * flat[:, 1]) < 0:
        flat[:, 1] *= -1  # the triangulator wants the ring counter-clockwise
    return np.asarray(mf.triangulate([np.ascontiguousarray(flat)]), dtype=np.int64)


def _signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    v = vertices[faces]
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)


def superellipse(half_width: float, half_height: float, exponent: float, count: int = 32) -> np.ndarray:
    """(count, 2) points of |x/a|^n + |y/b|^n = 1, counter-clockwise from +x; n = 2 an ellipse, large n a
    rounded rectangle."""
    t = np.linspace(0.0, 2 * math.pi, count, endpoint=False)
    c, s = np.cos(t), np.sin(t)
    return np.stack(
        [half_width * np.sign(c) * np.abs(c) ** (2 / exponent), half_height * np.sign(s) * np.abs(s) ** (2 / exponent)],
        axis=1,
    )


def cushion(
    size, centre, exponent: float = 5.0, vertical_exponent: float = 3.0, segments: int = 28, layers: int = 10
) -> mf.Manifold:
    """A superellipsoid filling the box ``size`` (x, y, z) at ``centre``: a stuffed pad with rounded edges.

    ``exponent`` shapes the plan (large: square corners), ``vertical_exponent`` the bulge of the sides.
    """
    sx, sy, sz = (float(v) / 2 for v in size)
    plan = superellipse(sx, sz, exponent, segments)
    theta = np.linspace(-0.5 * math.pi, 0.5 * math.pi, layers + 2)[1:-1] * 0.995
    c, s = np.cos(theta), np.sin(theta)
    scale = np.abs(c) ** (2 / vertical_exponent)
    heights = sy * np.sign(s) * np.abs(s) ** (2 / vertical_exponent)
    rings = np.stack(
        [np.stack([plan[:, 0] * k, np.full(len(plan), h), plan[:, 1] * k], axis=1) for k, h in zip(scale, heights)]
    )
    return loft(rings + np.asarray(centre, dtype=np.float64))


def band(width: float, thickness: float, bend: float, count: int = 16) -> np.ndarray:
    """(2 count, 2) ring of a curved strip's cross-section in (u, v): u across the strip in
    [-width/2, width/2], its front edge at v = bend * (2u/width)^2 (the strip's sides rise by ``bend``
    towards +v), its back edge ``thickness`` behind."""
    u = np.linspace(-width / 2, width / 2, count)
    front = bend * (2 * u / width) ** 2
    return np.concatenate([np.stack([u, front], 1), np.stack([u[::-1], front[::-1] - thickness], 1)])


def place_rings(profile: np.ndarray, points: np.ndarray, across: np.ndarray, up: np.ndarray) -> np.ndarray:
    """Rings (K, M, 3) from one 2D profile (M, 2) in (u, v), or one per point (K, M, 2), set at each of
    ``points`` (K, 3) with u along ``across`` and v along ``up`` (each (3,) or (K, 3))."""
    profile = np.asarray(profile, dtype=np.float64)
    if profile.ndim == 2:
        profile = np.broadcast_to(profile, (len(points),) + profile.shape)
    across = np.broadcast_to(np.asarray(across, dtype=np.float64), (len(points), 3))
    up = np.broadcast_to(np.asarray(up, dtype=np.float64), (len(points), 3))
    return points[:, None] + profile[..., :1] * across[:, None] + profile[..., 1:2] * up[:, None]


def curved_panel(
    width: float,
    height: float,
    thickness: float,
    bend: float,
    bottom,
    recline: float = 0.0,
    lumbar: float = 0.0,
    top_round: float = 6.0,
    layers: int = 12,
):
    """A back bent around the sitter: arc-shaped bands stacked upwards from ``bottom`` (x, y, z), leaning
    back by ``recline`` degrees, bulging forward by ``lumbar`` at mid-height, its top corners rounded
    (``top_round``: the exponent of the outline, large: square). The sides sit at the line through
    ``bottom``; the middle lies ``bend`` behind it."""
    h = np.linspace(0.0, 1.0, layers)
    widths = width * np.maximum((1 - (0.985 * h) ** top_round) ** (1 / top_round), 0.3)
    profiles = np.stack([band(w, thickness, bend * (w / width) ** 2) - [0.0, bend * (w / width) ** 2] for w in widths])
    x0, y0, z0 = bottom
    centres = np.stack(
        [
            np.full(layers, x0),
            y0 + h * height,
            z0 - math.tan(math.radians(recline)) * h * height + lumbar * np.sin(math.pi * h),
        ],
        axis=1,
    )
    return loft(place_rings(profiles, centres, [1.0, 0, 0], [0, 0, 1.0]))


def rounded_path(points, corner: float, spacing: float = 0.02) -> np.ndarray:
    """The polyline ``points`` (N, 3) with each inner corner replaced by a quadratic Bezier reaching ``corner``
    metres along both sides (so that a tube can follow it), resampled at ``spacing``."""
    points = np.asarray(points, dtype=np.float64)
    path = [points[:1]]
    for a, p, b in zip(points[:-2], points[1:-1], points[2:]):
        ca = min(corner, 0.45 * np.linalg.norm(a - p))
        cb = min(corner, 0.45 * np.linalg.norm(b - p))
        path.append(bezier([p + (a - p) * ca / np.linalg.norm(a - p), p, p + (b - p) * cb / np.linalg.norm(b - p)], 8))
    path.append(points[-1:])
    return resample(np.concatenate(path), spacing)
