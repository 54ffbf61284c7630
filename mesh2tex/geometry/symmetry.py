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

    check_array_shape(vertices, "azimuth_symmetries: vertices", ("V", 3))
    points = np.asarray(vertices, dtype=np.float64)
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
