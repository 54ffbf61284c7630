"""Closed re-makes of a surface from a sampled distance field: marching-cubes triangles and surface-net quads.

Any triangle set (open sheets, holes, intersecting or disconnected parts, non-manifold edges) is
turned into the boundary of a solid that is closed by construction:

1. the unsigned distance ``d`` from every node of a regular grid to the surface (exact near the
   surface, from dense surface samples; a distance transform elsewhere);
2. the *outside* is the part of ``{d > offset}`` connected to the grid's border; everything else
   (the surface thickened by ``offset``, and every cavity it encloses) is the solid;
3. the signed field ``phi`` (negative in the solid) is contoured either by marching cubes
   (:func:`marching_cubes`, triangles, for QuadriFlow) or by surface nets (:func:`surface_net_quads`,
   a pure-quad mesh directly: one quad per grid edge that leaves the solid).

The offset is what makes this robust: a part thinner than the grid spacing survives as a tube
of radius ``offset``, and gaps narrower than ``2 offset`` close, so the result has no holes and
no slivers at the chosen resolution.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from mesh2tex.checks import check_array_shape

# above this many grid nodes the exact distances are only computed in a band around the surface
_FULL_QUERY_NODES = 1_500_000


@dataclass(frozen=True)
class SolidField:
    """A signed field on a regular grid: ``phi < 0`` inside the closed solid, ``> 0`` outside.

    ``phi[i, j, k]`` is the value at ``origin + spacing * (i, j, k)``; the two outermost layers of
    nodes are always outside.
    """

    phi: np.ndarray  # (nx, ny, nz) float64
    origin: np.ndarray  # (3,) float64
    spacing: float
    offset: float

    @property
    def inside(self) -> np.ndarray:
        """(nx, ny, nz) bool."""
        return self.phi < 0


def _triangle_template(steps_base: int, steps_height: int) -> np.ndarray:
    """(P, 2) parameters (u, w) of rows across a triangle: ``steps_height + 1`` rows from the base to the
    apex, each with about ``steps_base (1 - w)`` steps; the point is ``(1 - w) (b + u (c - b)) + w a``."""
    rows = []
    for j in range(steps_height + 1):
        w = j / steps_height
        m = max(1, int(np.ceil(steps_base * (1.0 - w))))
        u = np.arange(m + 1) / m
        rows.append(np.stack([u, np.full(m + 1, w)], axis=1))
    return np.concatenate(rows)


def surface_samples(vertices: np.ndarray, faces: np.ndarray, spacing: float) -> np.ndarray:
    """Points on every triangle no further than about ``spacing`` apart (vertices included).

    Each triangle is covered by rows parallel to its longest edge (the base ``b c``, apex ``a``),
    ``ceil(height / spacing)`` rows apart and each row ``ceil(length / spacing)`` steps long, so a
    sliver gets points in proportion to its area, not to the square of its length.

    Args:
        vertices: (V, 3) float; faces: (T, 3) int; spacing: > 0.
    Returns:
        (P, 3) float64, duplicates at shared edges not removed.
    """
    check_array_shape(vertices, "surface_samples: vertices", ("V", 3))
    check_array_shape(faces, "surface_samples: faces", ("T", 3))
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    corners = v[f]  # (T, 3, 3)
    lengths = np.linalg.norm(corners[:, [1, 2, 0]] - corners[:, [2, 0, 1]], axis=2)  # edge opposite each corner
    apex = np.argmax(lengths, axis=1)  # the corner opposite the longest edge
    rows = np.arange(len(f))
    a = corners[rows, apex]
    b = corners[rows, (apex + 1) % 3]
    c = corners[rows, (apex + 2) % 3]
    base = lengths[rows, apex]
    area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    height = area2 / np.maximum(base, 1e-30)
    steps_base = np.maximum(1, np.ceil(base / spacing)).astype(np.int64)
    steps_height = np.maximum(1, np.ceil(height / spacing)).astype(np.int64)
    points = [v]
    need = (steps_base > 1) | (steps_height > 1)
    if need.any():
        pairs, group = np.unique(np.stack([steps_base[need], steps_height[need]], axis=1), axis=0, return_inverse=True)
        chosen_all = np.flatnonzero(need)
        group = group.reshape(-1)
        for g, (nb, nh) in enumerate(pairs):
            chosen = chosen_all[group == g]
            template = _triangle_template(int(nb), int(nh))
            u, w = template[:, 0][None, :, None], template[:, 1][None, :, None]
            bb, cc, aa = b[chosen][:, None], c[chosen][:, None], a[chosen][:, None]
            points.append(((1.0 - w) * (bb + u * (cc - bb)) + w * aa).reshape(-1, 3))
    return np.concatenate(points)


def solid_field(samples: np.ndarray, spacing: float, offset: float, tree: cKDTree | None = None) -> SolidField:
    """The closed solid around surface samples, thickened by ``offset`` (module docstring, steps 1-2).

    Args:
        samples: (P, 3) points on the surface, spaced well below ``spacing`` (:func:`surface_samples`).
        spacing: grid spacing; offset: thickening radius, at least about ``0.9 spacing`` so that
            every part, however thin, covers grid nodes.
        tree: a ``cKDTree`` of ``samples`` (built here when None).
    Returns:
        a :class:`SolidField` with ``phi = d - offset`` outside and ``-|d - offset|`` in the solid.
    """
    check_array_shape(samples, "solid_field: samples", ("P", 3))
    samples = np.asarray(samples, dtype=np.float64)
    tree = cKDTree(samples) if tree is None else tree
    pad = offset + 3.0 * spacing
    origin = samples.min(axis=0) - pad
    shape = tuple(int(n) for n in np.ceil((samples.max(axis=0) + pad - origin) / spacing).astype(int) + 1)
    total = int(np.prod(shape))
    far = offset + 2.0 * spacing
    if total <= _FULL_QUERY_NODES:
        grid = np.stack(np.meshgrid(*(np.arange(n) for n in shape), indexing="ij"), axis=-1).reshape(-1, 3)
        distance, _ = tree.query(origin + spacing * grid, k=1, distance_upper_bound=far)
        d = np.where(np.isfinite(distance), distance, far).reshape(shape)
    else:
        # a distance transform from the nodes nearest to samples bounds the distance within a node
        # diagonal; exact distances are computed only where it could be below ``far``
        marked = np.zeros(shape, dtype=bool)
        nearest = np.clip(np.rint((samples - origin) / spacing).astype(np.int64), 0, np.array(shape) - 1)
        marked[nearest[:, 0], nearest[:, 1], nearest[:, 2]] = True
        rough = ndimage.distance_transform_edt(~marked) * spacing
        band = np.argwhere(rough < far + spacing)
        distance, _ = tree.query(origin + spacing * band, k=1, distance_upper_bound=far)
        d = np.full(shape, far)
        d[band[:, 0], band[:, 1], band[:, 2]] = np.where(np.isfinite(distance), distance, far)
    free = d > offset
    labels, _ = ndimage.label(free)  # 6-connected
    outside = labels == labels[0, 0, 0]
    phi = np.where(outside, d - offset, -np.abs(d - offset) - 1e-9 * spacing)
    return SolidField(phi=phi, origin=origin, spacing=float(spacing), offset=float(offset))


def marching_cubes(field: SolidField) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of the solid's boundary (skimage's marching cubes), oriented outwards.

    Returns (V, 3) float64 and (T, 3) int64: a closed, edge-manifold surface.
    """
    from skimage import measure

    verts, tris, _, _ = measure.marching_cubes(
        field.phi, level=0.0, spacing=(field.spacing,) * 3, allow_degenerate=False
    )
    verts = verts.astype(np.float64) + field.origin
    tris = np.asarray(tris, dtype=np.int64)
    p = verts[tris]
    if np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() < 0:
        tris = np.ascontiguousarray(tris[:, ::-1])
    return verts, tris


def make_well_composed(inside: np.ndarray, max_rounds: int = 64) -> np.ndarray:
    """Add nodes to a solid until its voxel boundary is a 2-manifold (a well-composed set).

    Two configurations break manifoldness: in a 2x2 square of nodes, two diagonal nodes in and the
    other two out (an edge touched by four faces); in a 2x2x2 cube, only two opposite corners in, or
    only two opposite corners out (a vertex where two sheets meet). Each is removed by adding a node
    to the solid; this repeats until none is left (it ends: nodes are only ever added).

    Args:
        inside: (nx, ny, nz) bool, its border layer False.
    Returns:
        (nx, ny, nz) bool, a superset of ``inside``.
    """
    check_array_shape(inside, "make_well_composed: inside", ("X", "Y", "Z"))
    x = np.asarray(inside, dtype=bool).copy()
    corners = [(i, j, k) for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    for _ in range(max_rounds):
        changed = False
        for axis_u, axis_v in ((0, 1), (1, 2), (0, 2)):

            def view(du, dv):
                index = [slice(None)] * 3
                index[axis_u] = slice(du, x.shape[axis_u] - 1 + du)
                index[axis_v] = slice(dv, x.shape[axis_v] - 1 + dv)
                return tuple(index)

            a, b, c, d = x[view(0, 0)], x[view(1, 0)], x[view(0, 1)], x[view(1, 1)]
            diagonal = a & d & ~b & ~c
            anti = b & c & ~a & ~d
            if diagonal.any() or anti.any():
                x[view(1, 0)] |= diagonal
                x[view(0, 0)] |= anti
                changed = True

        def cube(i, j, k):
            return tuple(slice(o, n - 1 + o) for o, n in zip((i, j, k), x.shape))

        values = {c: x[cube(*c)] for c in corners}
        count = sum(values[c].astype(np.int8) for c in corners)
        for c in corners[:4]:
            opposite = tuple(1 - t for t in c)
            two_in = (count == 2) & values[c] & values[opposite]
            two_out = (count == 6) & ~values[c] & ~values[opposite]
            if two_in.any():
                neighbour = (1 - c[0], c[1], c[2])
                x[cube(*neighbour)] |= two_in
                changed = True
            if two_out.any():
                x[cube(*c)] |= two_out
                changed = True
        if not changed:
            return x
    raise RuntimeError("the voxel solid did not become well-composed")


_EDGE_CELLS = {  # per axis, the (u, v) axes and the 4 cells around a grid edge in counter-clockwise order
    0: ((1, 2), ((-1, -1), (0, -1), (0, 0), (-1, 0))),
    1: ((2, 0), ((-1, -1), (0, -1), (0, 0), (-1, 0))),
    2: ((0, 1), ((-1, -1), (0, -1), (0, 0), (-1, 0))),
}


def surface_net_quads(field: SolidField) -> tuple[np.ndarray, np.ndarray]:
    """A closed, manifold pure-quad mesh of the solid's boundary (surface nets on a well-composed solid).

    One quad per grid edge from a solid node to an outside node, its four corners the grid cells
    around that edge; each cell's vertex is the mean of the points where ``phi`` crosses zero on the
    cell's edges. Quads are oriented outwards.

    Args:
        field: a :class:`SolidField`.
    Returns:
        (V, 3) float64 vertices and (F, 4) int64 quads; F = 0 when the solid is empty.
    """
    inside = make_well_composed(field.inside)
    phi = np.where(inside, np.minimum(field.phi, -1e-6 * field.spacing), np.maximum(field.phi, 1e-6 * field.spacing))
    shape = np.array(phi.shape)
    quads_cells = []
    for axis in range(3):
        (u, v), ring = _EDGE_CELLS[axis]
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        a, b = inside[tuple(lo)], inside[tuple(hi)]
        crossing = np.argwhere(a != b)  # node p with p and p + e_axis on different sides
        outward = a[tuple(crossing.T)]  # solid at p: the normal points along +axis
        cells = []
        for du, dv in ring:
            c = crossing.copy()
            c[:, u] += du
            c[:, v] += dv
            cells.append(c)
        cells = np.stack(cells, axis=1)  # (E, 4, 3)
        cells[~outward] = cells[~outward][:, ::-1]
        quads_cells.append(cells)
    cells = np.concatenate(quads_cells)
    if len(cells) == 0:
        return np.zeros((0, 3)), np.zeros((0, 4), dtype=np.int64)
    flat = np.ravel_multi_index(cells.reshape(-1, 3).T, tuple(shape - 1))
    used, inverse = np.unique(flat, return_inverse=True)
    quads = inverse.reshape(-1, 4).astype(np.int64)
    cell_index = np.stack(np.unravel_index(used, tuple(shape - 1)), axis=1)
    # zero crossings on the 12 edges of every used cell
    total = np.zeros((len(used), 3))
    count = np.zeros(len(used))
    offsets = np.array([(i, j, k) for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    values = np.stack([phi[tuple((cell_index + o).T)] for o in offsets], axis=1)  # (C, 8)
    for p, q in [(p, q) for p in range(8) for q in range(p + 1, 8) if np.abs(offsets[p] - offsets[q]).sum() == 1]:
        va, vb = values[:, p], values[:, q]
        sign_change = (va < 0) != (vb < 0)
        t = np.clip(va / np.where(sign_change, va - vb, 1.0), 0.0, 1.0)
        point = offsets[p][None, :] + t[:, None] * (offsets[q] - offsets[p])[None, :]
        total += np.where(sign_change[:, None], point, 0.0)
        count += sign_change
    local = total / np.maximum(count, 1)[:, None]
    vertices = field.origin + field.spacing * (cell_index + local)
    return vertices, quads
