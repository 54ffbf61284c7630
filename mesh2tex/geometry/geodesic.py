"""Geodesic charts of a triangle mesh: the exponential map, walked face by face, and tangent frames
oriented by a direction field.

A chart is a square grid of points around a centre x on the surface, each reached by the straightest
geodesic from x: the grid offset (a, b) in x's tangent frame (r, u) is the direction
(a r + b u) / |(a, b)| walked for the length |(a, b)| along the surface,

    y(a, b) = exp_x(a r + b u)

as the convolutions of surface-aware texture synthesis sample their neighbourhoods (Kovacs et al.,
"Surface-aware mesh texture synthesis with pre-trained 2D CNNs", 2024, Eq. 2). Read through a
texture, a chart is an image of the surface as it is, with no camera's foreshortening and across the
UV atlas's seams.

**The walk.** A point moves in a straight line inside its face until it meets an edge (the first
barycentric coordinate to reach zero); there the direction is unfolded onto the neighbouring face
(rotated about the shared edge, its component along the edge kept), and the walk goes on with the
length left. Faces are joined by their welded vertices (equal positions), so a walk crosses the seams
that an atlas splits vertices on. A walk that reaches a boundary edge, a non-manifold edge, a
degenerate face or more than ``max_crossings`` edges stops there and is marked invalid. So is a walk
that has come back around a thin part: where its end lies nearer its start than ``min_chord`` times
the length walked (a walk half way around a tube ends 2 / pi of its length away; on a unit sphere a
chart's corner 0.45 away keeps 0.99), so that a chart shows a leg's near side, not its far side
folded over it.

**The frames.** At a centre on face f with unit normal n, ``u`` is the direction field's tangent on f
(:mod:`mesh2tex.geometry.direction_field`: by default the mesh's up, +y, projected onto the plane; x
where the up is within 6 degrees of n) and ``r = u x n``, so that (r, u, n) is right-handed and a
chart shows the surface as seen from outside, u up. A roll angle turns both about n (a random one
per chart for the field ``"none"``).

Conventions: positions (V, 3) float, faces (T, 3) int; barycentric coordinates (n, 3) weight the
face's corners in order.
"""

from __future__ import annotations

import numpy as np

from mesh2tex.geometry.direction_field import projected_axis
from mesh2tex.geometry.hierarchy import polygon_edge_neighbors

_EPS = 1e-12


def weld_positions(positions: np.ndarray) -> np.ndarray:
    """(V,) int64: one id per distinct position, so that the copies of a vertex split on a seam share it."""
    _, welded = np.unique(np.asarray(positions, dtype=np.float64), axis=0, return_inverse=True)
    return welded.reshape(-1).astype(np.int64)


class SurfaceWalker:
    """Geodesic walks and tangent frames on one triangle mesh (module docstring).

    positions (V, 3) and faces (T, 3); the copies of a vertex split on an atlas seam (equal positions)
    are joined, so ``face`` ids are the given faces' and walks cross seams.
    """

    def __init__(self, positions: np.ndarray, faces: np.ndarray, max_crossings: int = 256, min_chord: float = 0.7):
        self.positions = np.asarray(positions, dtype=np.float64)
        self.faces = np.asarray(faces, dtype=np.int64)
        self.max_crossings = int(max_crossings)
        self.min_chord = float(min_chord)
        self.corners = weld_positions(self.positions)[self.faces]  # (T, 3) welded ids
        # (T, 3): the face across the edge opposite each corner, i.e. edge (i + 1, i + 2); -1 on a boundary
        self.neighbours = np.roll(polygon_edge_neighbors(self.corners), -1, axis=1)
        v = self.positions[self.faces]  # (T, 3, 3)
        self.vertices = v
        cross = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        double_area = np.linalg.norm(cross, axis=1)
        self.area = double_area / 2
        self.usable = double_area > _EPS * max(float(np.abs(v).max(initial=1.0)) ** 2, 1.0)
        self.normals = cross / np.maximum(double_area, _EPS)[:, None]
        # Gradient of barycentric coordinate i: n x (edge opposite i, from corner i+1 to i+2) / (2 area).
        self.gradients = (
            np.stack([np.cross(self.normals, v[:, (i + 2) % 3] - v[:, (i + 1) % 3]) for i in range(3)], axis=1)
            / np.maximum(double_area, _EPS)[:, None, None]
        )
        self.along, self.inward = self._edge_frames()

    def _edge_frames(self) -> tuple[np.ndarray, np.ndarray]:
        """Per face and edge (opposite corner i), (T, 3, 3) each: the edge's unit direction (corner i+1 to
        i+2), and the unit direction perpendicular to it into the neighbour across it (0 on a boundary)."""
        count = len(self.faces)
        along, inward = np.zeros((count, 3, 3)), np.zeros((count, 3, 3))
        for edge in range(3):
            a = self.vertices[:, (edge + 1) % 3]
            b = self.vertices[:, (edge + 2) % 3]
            along[:, edge] = (b - a) / np.maximum(np.linalg.norm(b - a, axis=1, keepdims=True), _EPS)
            neighbour = self.neighbours[:, edge]
            has = neighbour >= 0
            # The neighbour's corner off the shared edge: the one whose welded id is neither end's.
            ends = self.corners[has, (edge + 1) % 3], self.corners[has, (edge + 2) % 3]
            theirs = self.corners[neighbour[has]]
            off = ((theirs != ends[0][:, None]) & (theirs != ends[1][:, None])).argmax(1)
            towards = self.vertices[neighbour[has], off] - a[has]
            towards -= (towards * along[has, edge]).sum(1, keepdims=True) * along[has, edge]
            towards /= np.maximum(np.linalg.norm(towards, axis=1, keepdims=True), _EPS)
            inward[has, edge] = towards
        return along, inward

    def sample(self, count: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """``count`` points uniform over the surface's area: faces (count,) and barycentrics (count, 3)."""
        weights = np.where(self.usable, self.area, 0.0)
        if not weights.sum() > 0:
            raise ValueError("SurfaceWalker.sample: the mesh has no triangle of non-zero area")
        face = rng.choice(len(self.faces), size=count, p=weights / weights.sum())
        s, t = np.sqrt(rng.random(count)), rng.random(count)
        bary = np.stack([1 - s, s * (1 - t), s * t], axis=1)
        return face, bary

    def frames(self, face: np.ndarray, roll: np.ndarray | float = 0.0, field: np.ndarray | None = None) -> np.ndarray:
        """(n, 2, 3): the tangent frame (r, u) at points on ``face`` (n,), u the direction ``field`` (T, 3)
        (unit tangents per face, :mod:`mesh2tex.geometry.direction_field`; the mesh's up projected when
        None) turned by ``roll`` radians about the face normal, r = u x n."""
        normal = self.normals[face]
        u = projected_axis(normal, "y") if field is None else np.asarray(field, dtype=np.float64)[face]
        r = np.cross(u, normal)
        roll = np.broadcast_to(np.asarray(roll, dtype=np.float64), face.shape)[:, None]
        cos, sin = np.cos(roll), np.sin(roll)
        return np.stack([cos * r + sin * u, cos * u - sin * r], axis=1)

    def point(self, face: np.ndarray, bary: np.ndarray) -> np.ndarray:
        """(n, 3) positions of barycentrics (n, 3) on ``face`` (n,)."""
        return (self.vertices[face] * bary[:, :, None]).sum(1)

    def walk(self, face: np.ndarray, bary: np.ndarray, step: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """exp_x(step): from points (``face`` (n,), ``bary`` (n, 3)) along tangent vectors ``step`` (n, 3)
        (in the plane of the start face) for their length, on the surface. Returns the faces (n,),
        barycentrics (n, 3) and valid (n,) bool (False where a walk stopped early, its point where it
        stopped, or came back around a thin part)."""
        face = np.array(face, dtype=np.int64)  # a copy: the walk moves it
        start = self.point(face, np.asarray(bary, dtype=np.float64))
        position = start.copy()
        length = np.linalg.norm(step, axis=1)
        direction = step / np.maximum(length, _EPS)[:, None]
        remaining = length.copy()
        valid = self.usable[face].copy()
        active = np.flatnonzero(valid & (remaining > 0))
        for _ in range(self.max_crossings):
            if len(active) == 0:
                break
            active = self._advance(active, face, position, direction, remaining, valid)
        valid[active] = False  # still walking after max_crossings edges
        valid &= np.linalg.norm(position - start, axis=1) >= self.min_chord * length - 1e-9
        return face, self._barycentric(face, position), valid

    def _barycentric(self, face: np.ndarray, position: np.ndarray, gradients: np.ndarray | None = None) -> np.ndarray:
        """(n, 3) barycentrics of points in the planes of ``face``, clipped to the triangle and renormalised
        (``gradients``: ``self.gradients[face]`` when the caller has them)."""
        g = self.gradients[face] if gradients is None else gradients
        # lambda_i = grad lambda_i . (p - a corner on the edge opposite i): corners 1, 2, 0.
        lam = ((position[:, None, :] - self.vertices[face][:, [1, 2, 0]]) * g).sum(2)
        lam = np.clip(lam, 0.0, None)
        return lam / np.maximum(lam.sum(1, keepdims=True), _EPS)

    def _advance(self, active, face, position, direction, remaining, valid) -> np.ndarray:
        """Move the ``active`` walks to the end of their length or the next edge (updating the arrays in
        place); returns the walks still going."""
        f, p, d = face[active], position[active], direction[active]
        g = self.gradients[f]
        lam = self._barycentric(f, p, g)
        rate = np.einsum("nij,nj->ni", g, d)  # d(lambda_i)/dt
        with np.errstate(divide="ignore", invalid="ignore"):
            exit_time = np.where(rate < -1e-15, -lam / rate, np.inf)
        edge = exit_time.argmin(1)
        time = exit_time[np.arange(len(f)), edge]
        done = remaining[active] <= time
        travel = np.where(done, remaining[active], time)
        position[active] = p + travel[:, None] * d
        remaining[active] -= travel
        going = active[~done]
        if len(going) == 0:
            return going
        g_edge = edge[~done]
        f_old = face[going]
        nxt = self.neighbours[f_old, g_edge]
        blocked = nxt < 0
        blocked[~blocked] = ~self.usable[nxt[~blocked]]
        valid[going[blocked]] = False
        going, g_edge, f_old, nxt = going[~blocked], g_edge[~blocked], f_old[~blocked], nxt[~blocked]
        direction[going] = self._unfold(f_old, g_edge, direction[going])
        face[going] = nxt
        return going

    def _unfold(self, face, edge, direction) -> np.ndarray:
        """The unit directions (n, 3) leaving ``face`` across its edge opposite corner ``edge``, carried onto
        the neighbour there: the component along the edge kept, the rest turned into the neighbour's plane."""
        along, inward = self.along[face, edge], self.inward[face, edge]
        tangential = (direction * along).sum(1)
        across = np.sqrt(np.clip(1 - tangential**2, 0.0, None))
        return tangential[:, None] * along + across[:, None] * inward


def chart_offsets(size: int, spacing: float) -> np.ndarray:
    """(size * size, 2): the grid's (a, b) offsets, row-major from the top-left, a to the right and b up,
    ``spacing`` apart and centred on the chart's middle."""
    centre = (size - 1) / 2
    rows, cols = np.meshgrid(np.arange(size), np.arange(size), indexing="ij")
    return np.stack([(cols - centre) * spacing, (centre - rows) * spacing], axis=-1).reshape(-1, 2)


def geodesic_charts(
    walker: SurfaceWalker, face: np.ndarray, bary: np.ndarray, frames: np.ndarray, size: int, spacing: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Charts of ``size`` x ``size`` points ``spacing`` apart around each centre (``face`` (n,), ``bary``
    (n, 3)) with tangent frames (n, 2, 3) (:meth:`SurfaceWalker.frames`). Returns faces (n, size, size),
    barycentrics (n, size, size, 3) and valid (n, size, size) bool."""
    offsets = chart_offsets(size, spacing)  # (G*G, 2)
    n, points = len(face), len(offsets)
    steps = np.einsum("pk,nkj->npj", offsets, frames).reshape(-1, 3)
    faces, barys, valid = walker.walk(np.repeat(face, points), np.repeat(bary, points, axis=0), steps)
    return faces.reshape(n, size, size), barys.reshape(n, size, size, 3), valid.reshape(n, size, size)


__all__ = ["SurfaceWalker", "chart_offsets", "geodesic_charts", "weld_positions"]
