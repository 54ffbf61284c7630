"""Turns about the vertical axis that leave a shape as it was: the poses a photo cannot tell apart.

A backless bench photographed from the front and from the back shows the same picture, and a round
stool every azimuth the same one; a pose found half a turn off on such a shape is no error. The pose
errors of the transfer protocols and of ``benchmarks/outside_transfer.py`` are counted up to these
turns (:func:`mesh2tex.nn.pose.symmetric_azimuth_error`).
"""

from __future__ import annotations

import numpy as np

from mesh2tex.checks import check_array_shape


def azimuth_symmetries(vertices: np.ndarray, step: float = 5.0, tolerance: float = 0.03) -> list[float]:
    """The turns (degrees, 0 first) about the vertical (y) axis through the vertices' mean that map the
    shape onto itself.

    vertices: (V, 3), y up. A turn counts when the turned vertices lie within ``tolerance`` bounding-box
    diagonals of the unturned ones and the unturned within as much of the turned (the 99th percentile of
    the nearest distances, both ways: every part lands on a part). Turns are tried every ``step``
    degrees; a symmetry shows as a run of close turns (the tolerance admits a few degrees), of which the
    closest is kept. Every turn when all are close (a round shape); ``[0.0]`` for a chair with a back.
    """
    from scipy.spatial import cKDTree

    points = check_vertices(vertices, "azimuth_symmetries")
    # A vertex set that a turn maps onto itself has its mean on the turn's axis; the bounding box's centre
    # need not be (a three-legged stool's box is off its axis)
    points = points - points.mean(axis=0)
    diagonal = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    tree = cKDTree(points)
    angles = np.arange(0.0, 360.0, step)
    distances = np.empty(len(angles))
    for i, degrees in enumerate(angles):
        c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
        turned = points @ np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])
        there, back = tree.query(turned)[0], cKDTree(turned).query(points)[0]
        distances[i] = max(np.percentile(there, 99), np.percentile(back, 99))
    close = distances < tolerance * diagonal
    if close.all():
        return [float(a) for a in angles]
    turns, n = [], len(angles)
    for i in range(n):
        if close[i] and not close[i - 1]:  # a run of close turns starts here (circularly)
            run = [i]
            while close[(run[-1] + 1) % n]:
                run.append((run[-1] + 1) % n)
            turns.append(float(angles[min(run, key=lambda j: distances[j])]))
    return sorted(turns) or [0.0]  # a degenerate shape (every vertex at one point): the plain error


def mirror_axis(
    vertices: np.ndarray, triangles: np.ndarray, tolerance: float = 0.03, samples: int = 20000
) -> int | None:
    """The axis (0: x, 2: z) whose vertical plane through the bounding box's centre mirrors the surface onto
    itself, or None: the plane a photo's other side can be read across (a chair's or a car's left and
    right).

    vertices: (V, 3), y up; triangles: (F, 3). ``samples`` points spread over the surface by area (seeded:
    the answer repeats) are mirrored; the plane counts when the mirrored points lie within ``tolerance``
    bounding-box diagonals of the unmirrored ones and those within as much of the mirrored (the 99th
    percentile of the nearest distances, both ways, as :func:`azimuth_symmetries`); of two that count,
    the closer. Surface points, not vertices: a remeshed surface's vertices need not mirror where the
    surface does.
    """
    from scipy.spatial import cKDTree

    check_array_shape(triangles, "mirror_axis: triangles", ("F", 3))
    points = surface_points(check_vertices(vertices, "mirror_axis"), triangles, samples)
    # The plane of a mirror symmetry halves the bounding box (the NOC frame's centre, where the mirrored
    # NOC is 1 - c); the points' mean need not lie on it when a part is thicker on one side.
    lower, upper = points.min(axis=0), points.max(axis=0)
    points = points - 0.5 * (lower + upper)
    diagonal = float(np.linalg.norm(upper - lower))
    if diagonal <= 0:
        return None
    tree = cKDTree(points)
    distances = {}
    for axis in (0, 2):
        mirrored = points.copy()
        mirrored[:, axis] *= -1.0
        there, back = tree.query(mirrored)[0], cKDTree(mirrored).query(points)[0]
        distances[axis] = max(np.percentile(there, 99), np.percentile(back, 99)) / diagonal
    axis = min(distances, key=distances.get)
    return axis if distances[axis] < tolerance else None


def check_vertices(vertices: np.ndarray, function: str) -> np.ndarray:
    """(V, 3) float64 vertices, or ValueError naming ``function``."""
    check_array_shape(vertices, f"{function}: vertices", ("V", 3))
    return np.asarray(vertices, dtype=np.float64)


def surface_points(vertices: np.ndarray, triangles: np.ndarray, count: int, seed: int = 0) -> np.ndarray:
    """(count, 3) points spread over the triangles (F, 3) of vertices (V, 3) by area, uniformly within
    each; the vertices themselves when the surface has no area."""
    corners = np.asarray(vertices, dtype=np.float64)[np.asarray(triangles, dtype=np.int64)]  # (F, 3, 3)
    areas = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    if len(corners) == 0 or areas.sum() <= 0:
        return np.asarray(vertices, dtype=np.float64)
    rng = np.random.default_rng(seed)
    chosen = rng.choice(len(corners), size=count, p=areas / areas.sum())
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1.0  # fold the square's far half back into the triangle
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    c = corners[chosen]
    return c[:, 0] + u[:, None] * (c[:, 1] - c[:, 0]) + v[:, None] * (c[:, 2] - c[:, 0])


def mirrored_azimuth(azimuth: float, axis: int) -> float:
    """The azimuth (degrees, [0, 360)) of the camera mirrored across the vertical plane normal to ``axis``
    (0: x, 2: z) through the origin: an orbit camera at (cos e sin a, sin e, cos e cos a) goes to -a or
    180 - a. What it sees is the unmirrored camera's picture flipped left to right."""
    if axis not in (0, 2):
        raise ValueError(f"mirrored_azimuth: axis {axis} must be 0 (x) or 2 (z)")
    return float((-azimuth if axis == 0 else 180.0 - azimuth) % 360.0)
