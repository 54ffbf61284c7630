"""Tangent direction fields on a triangle mesh: which way is "up" in each face's tangent plane.

A pattern laid on a surface needs a direction at every point (a stripe runs along it, a brick's
rows across it). Two fields, one unit tangent per face, both guided by one axis of the mesh's
working frame (``axis``: y, the mesh's up, by default; x or z):

- ``up``: the axis projected onto the face's plane, as the seed paper's Gram-Schmidt frames are
  (Kovacs et al. 2024, Sec. 3.1). Where the axis is within 6 degrees of the normal (a seat, a roof)
  it is undefined and the next axis (x for y; y for x and z) is used instead, so the field jumps by
  a right angle at the edge of every face that looks along the axis.
- ``smooth``: the smoothest field that follows the projected axis where the surface is steep, the
  smoother tangent frames the paper suggests (Fisher et al. 2007). Each face's direction is a
  complex number z_f in the face's own frame; across an edge a direction is carried onto the
  neighbour by the rotation r_fg that keeps its angle to the shared edge (the discrete Levi-Civita
  connection), and the field minimises

      sum over interior edges  w_fg |z_g - r_fg z_f|^2  +  lam sum over faces  A_f s_f |z_f - q_f|^2,

  q_f the projected axis (unit), s_f = sin^2 of the angle between axis and normal (1 on a wall, 0
  on a seat), A_f the face's area, w_fg = l^2 / (A_f + A_g) for the shared edge's length l (the
  Dirichlet energy of a piecewise-constant field) and lam = 1 / (REACH L)^2 for the mesh's bounding-box
  diagonal L, so the field leaves the axis over about a twentieth of the object. Where the axis is
  undefined the field is filled in from the steep faces around: on a chair's seat, the back's and
  the front's up folded over their edges near them (a stripe running down the back goes on over the
  edge) and the sides' folded in near the sides, turning round a singular point in the middle; a
  closed surface must have such points (on a sphere, two). A straight field on the seat (``up``'s
  fallback) has none there but jumps at the seat's edges (docs/results/nca.md measures both).
  A linear solve (the normal equations, a sparse Hermitian system); then z_f is normalised. An edge
  whose two faces are wound against each other takes no smoothing across it; a part with no steep
  face keeps the ``up`` field's fallback (a small alignment everywhere keeps the system regular).

Conventions: a field is (T, 3) float64, unit and in each face's plane (zero rows on degenerate faces).
"""

from __future__ import annotations

import numpy as np

FIELDS = ("up", "smooth")  # the fields of tangent_field; "none" (random roll, no field) is the caller's
AXES = ("x", "y", "z")  # the guiding axis, in the mesh's working frame (y up)
_STEEP = 0.1  # |axis projected| below this (within ~6 degrees of the normal): the axis is undefined there
_FLOOR = 1e-3  # alignment kept on faces that look along the axis: regular system, parts with no steep face
REACH = 0.05  # the field leaves the axis over about this share of the mesh's diagonal (lam = 1 / (REACH L)^2)
_EPS = 1e-12


def axis_vector(axis: str) -> np.ndarray:
    """(3,) unit vector of ``axis`` (x, y or z)."""
    if axis not in AXES:
        raise ValueError(f"direction axis must be one of {', '.join(AXES)}, got {axis!r}")
    return np.eye(3)[AXES.index(axis)]


def projected_axis(normals: np.ndarray, axis: str = "y") -> np.ndarray:
    """(T, 3) the ``up`` field: ``axis`` projected onto each plane of unit ``normals`` (T, 3), normalised;
    the next axis (x for y, else y) where ``axis`` is within ~6 degrees of the normal."""
    guide = axis_vector(axis)
    fallback = axis_vector("x" if axis == "y" else "y")
    tangent = guide - (normals @ guide)[:, None] * normals
    steep = np.linalg.norm(tangent, axis=1) < _STEEP
    other = fallback - (normals @ fallback)[:, None] * normals
    tangent = np.where(steep[:, None], other, tangent)
    return tangent / np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), _EPS)


def tangent_field(walker, kind: str = "up", axis: str = "y") -> np.ndarray:
    """(T, 3) unit tangent per face of ``walker``'s mesh (a :class:`mesh2tex.geometry.geodesic.SurfaceWalker`):
    the ``up`` or ``smooth`` field guided by ``axis`` (module docstring)."""
    if kind == "up":
        return projected_axis(walker.normals, axis)
    if kind != "smooth":
        raise ValueError(f"direction field must be one of {', '.join(FIELDS)}, got {kind!r}")
    return smooth_field(walker, axis)


def _face_frames(vertices: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each face's frame (e1, e2), (T, 3) each: e1 along its first edge, e2 = n x e1."""
    e1 = vertices[:, 1] - vertices[:, 0]
    e1 = e1 / np.maximum(np.linalg.norm(e1, axis=1, keepdims=True), _EPS)
    return e1, np.cross(normals, e1)


def _interior_edges(walker) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The edges the smoothing crosses: faces f < g (n,) each, and the corner i of f opposite the shared edge
    (n,); both faces usable and wound alike (g runs the edge the other way)."""
    neighbours, corners = walker.neighbours, walker.corners
    f, i = np.nonzero(neighbours >= 0)
    g = neighbours[f, i]
    keep = (f < g) & walker.usable[f] & walker.usable[g]
    f, i, g = f[keep], i[keep], g[keep]
    a, b = corners[f, (i + 1) % 3], corners[f, (i + 2) % 3]  # f runs the edge a -> b
    against = np.zeros(len(f), dtype=bool)
    for j in range(3):  # g wound alike when one of its edges runs b -> a
        against |= (corners[g, (j + 1) % 3] == b) & (corners[g, (j + 2) % 3] == a)
    return f[against], g[against], i[against]


def _edge_turns(walker, e1: np.ndarray, e2: np.ndarray):
    """The interior edges (f, g, i as :func:`_interior_edges`), each shared edge's squared length (n,) and
    the rotation r_fg (n,) complex that carries a direction in f's frame (e1, e2) to g's, keeping its angle
    to the edge."""
    f, g, i = _interior_edges(walker)
    edge = walker.vertices[f, (i + 2) % 3] - walker.vertices[f, (i + 1) % 3]
    angle_f = np.arctan2((edge * e2[f]).sum(1), (edge * e1[f]).sum(1))
    angle_g = np.arctan2((edge * e2[g]).sum(1), (edge * e1[g]).sum(1))
    return f, g, (edge**2).sum(1), np.exp(1j * (angle_g - angle_f))


def smooth_field(walker, axis: str = "y") -> np.ndarray:
    """(T, 3) the ``smooth`` field of ``walker``'s mesh guided by ``axis`` (module docstring)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.linalg import spsolve

    vertices, normals, area = walker.vertices, walker.normals, walker.area
    count = len(vertices)
    e1, e2 = _face_frames(vertices, normals)
    guide = projected_axis(normals, axis)  # (T, 3) unit, the fallback where the axis is undefined
    target = (guide * e1).sum(1) + 1j * (guide * e2).sum(1)  # q_f
    along = np.linalg.norm(axis_vector(axis) - (normals @ axis_vector(axis))[:, None] * normals, axis=1)
    strength = np.where(along < _STEEP, 0.0, along**2) + _FLOOR  # s_f (T,)
    extent = np.linalg.norm(np.ptp(vertices.reshape(-1, 3), axis=0))
    weight = np.where(walker.usable, area * strength, 0.0) / max(REACH * extent, _EPS) ** 2  # lam A_f s_f

    f, g, length2, turn = _edge_turns(walker, e1, e2)  # turn: z_g = r_fg z_f for a direction carried across
    w = length2 / np.maximum(area[f] + area[g], _EPS)
    # Normal equations of the energy: (L + diag(weight)) z = weight q, L the connection Laplacian.
    rows = np.concatenate([f, g, g, f, np.arange(count)])
    cols = np.concatenate([f, g, f, g, np.arange(count)])
    values = np.concatenate([w, w, -w * turn, -w * np.conj(turn), weight]).astype(np.complex128)
    system = coo_matrix((values, (rows, cols)), shape=(count, count)).tocsc()
    unusable = ~walker.usable  # keep the degenerate faces' rows regular
    if unusable.any():
        system = system + coo_matrix((unusable.astype(np.complex128), (np.arange(count),) * 2), (count,) * 2).tocsc()
    z = spsolve(system, weight * target)
    field = z.real[:, None] * e1 + z.imag[:, None] * e2
    norm = np.linalg.norm(field, axis=1, keepdims=True)
    field = np.where(norm > _EPS, field / np.maximum(norm, _EPS), guide)  # a singular face: the guide
    return np.where(walker.usable[:, None], field, 0.0)


def field_turns(walker, field: np.ndarray) -> np.ndarray:
    """(n,) degrees in [0, 180]: across each interior edge (:func:`_interior_edges`), the angle between the
    neighbour's direction and this face's ``field`` (T, 3) carried over the edge (0 for a field that does
    not turn); a jump of the ``up`` field shows as a turn near 90."""
    e1, e2 = _face_frames(walker.vertices, walker.normals)
    f, g, _, turn = _edge_turns(walker, e1, e2)
    z_f = (field[f] * e1[f]).sum(1) + 1j * (field[f] * e2[f]).sum(1)
    z_g = (field[g] * e1[g]).sum(1) + 1j * (field[g] * e2[g]).sum(1)
    carried = z_f * turn
    return np.degrees(np.abs(np.angle(z_g * np.conj(carried))))
