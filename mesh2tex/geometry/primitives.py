"""Procedural quad meshes: the cube-sphere the cellular automaton trains on, and quad subdivision.

Both return plain arrays: vertices (V, 3) float32 and quads (F, 4) int64 in cyclic order,
counter-clockwise seen from outside (outward normals).
"""

from __future__ import annotations

import numpy as np

from mesh2tex.checks import check_array_shape

# Each cube face: (normal axis, sign); its grid spans the other two axes so that (u, v, normal) is right-handed.
_CUBE_FACES = ((0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0), (2, 1.0), (2, -1.0))


def cube_sphere(subdivisions: int, radius: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A quad sphere: each face of a cube split into ``subdivisions`` x ``subdivisions`` quads.

    Points are placed with the equal-angle (tangent) mapping before being pushed to the sphere, which
    keeps the quads within a factor ~1.3 of each other in size (the plain projection: ~2.6). Edge
    valence is 4 everywhere except the 8 cube corners (3). Returns vertices (6 n^2 + 2, 3) float32 on
    the sphere of ``radius`` and quads (6 n^2, 4) int64.
    """
    n = int(subdivisions)
    if n < 1:
        raise ValueError(f"subdivisions must be >= 1, got {subdivisions}")
    t = np.tan(np.linspace(-np.pi / 4, np.pi / 4, n + 1))  # equal-angle grid on [-1, 1]
    points, quads = [], []
    for axis, sign in _CUBE_FACES:
        u_axis, v_axis = (axis + 1) % 3, (axis + 2) % 3
        uu, vv = np.meshgrid(t, t, indexing="ij")  # (n+1, n+1)
        p = np.zeros((n + 1, n + 1, 3))
        p[..., axis] = sign
        p[..., u_axis] = uu
        p[..., v_axis] = vv * sign  # flip v on the negative faces so that every face winds outward
        base = len(points) * (n + 1) ** 2
        index = base + np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
        quads.append(np.stack([index[:-1, :-1], index[1:, :-1], index[1:, 1:], index[:-1, 1:]], axis=-1).reshape(-1, 4))
        points.append(p.reshape(-1, 3))
    vertices = np.concatenate(points)
    vertices /= np.linalg.norm(vertices, axis=1, keepdims=True)
    # Weld the copies on the cube's edges and corners.
    keys = np.round(vertices * 1e6).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)  # keep vertices in order of first appearance
    remap = np.empty_like(order)
    remap[order] = np.arange(order.size)
    welded = vertices[first[order]] * radius
    return welded.astype(np.float32), remap[inverse.reshape(-1)][np.concatenate(quads)].astype(np.int64)


def subdivide_quads(vertices: np.ndarray, quads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split every quad into four at its edge midpoints and centre (no smoothing: the surface stays put).

    vertices (V, 3), quads (F, 4) -> vertices (V + E + F, 3) float32, quads (4 F, 4) int64, with the
    original vertices first and each shared edge's midpoint created once, so the result is welded
    wherever the input was.
    """
    check_array_shape(vertices, "subdivide_quads: vertices", ("V", 3))
    check_array_shape(quads, "subdivide_quads: quads", ("F", 4))
    vertices = np.asarray(vertices, dtype=np.float64)
    quads = np.asarray(quads, dtype=np.int64)
    v, f = vertices.shape[0], quads.shape[0]
    edges = np.stack([quads, np.roll(quads, -1, axis=1)], axis=-1).reshape(-1, 2)  # (4F, 2): edge k of face f at 4f + k
    unique, edge_id = np.unique(np.sort(edges, axis=1), axis=0, return_inverse=True)
    edge_id = edge_id.reshape(f, 4) + v
    centre_id = v + unique.shape[0] + np.arange(f)
    new_vertices = np.concatenate([vertices, vertices[unique].mean(axis=1), vertices[quads].mean(axis=1)])
    children = []
    for k in range(4):
        # Corner k, then the midpoint of edge k (k -> k+1), the centre, and the midpoint of edge k-1.
        children.append(np.stack([quads[:, k], edge_id[:, k], centre_id, edge_id[:, (k - 1) % 4]], axis=1))
    return new_vertices.astype(np.float32), np.stack(children, axis=1).reshape(-1, 4)


DEFAULT_SPHERE_SUBDIVISIONS = 32  # 6,146 vertices: the automaton's training sphere (docs/nca.md: why not 24)


def load_surface(spec: str, subdivide: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The mesh a cellular automaton runs on, normalised to the unit ball (bounding-box centre at the
    origin, farthest vertex at distance 1): :func:`unit_surface` of :func:`read_surface`.

    ``spec``: "sphere" or "sphere:N" (a cube-sphere of N subdivisions), a prepared shape (.npz: its
    finest quads) or a mesh file (its triangles, merged and cleaned by :func:`load_mesh`).
    ``subdivide``: split every face into four that many times (denser cells, a finer texture).
    Returns vertices (V, 3) float32 and faces (F, 4) quads or (F, 3) triangles int64. Bad input
    raises :class:`InputError` naming the file.
    """
    return unit_surface(*read_surface(spec), subdivide=subdivide, name=spec)


def read_surface(spec: str) -> tuple[np.ndarray, np.ndarray]:
    """The mesh ``spec`` names (see :func:`load_surface`) as it is: vertices (V, 3) float64, faces (F, 4)
    or (F, 3) int64, at least one. Read it once and give it to :func:`unit_surface` for each subdivision."""
    from mesh2tex.errors import InputError

    if spec == "sphere" or spec.startswith("sphere:"):
        count = spec.partition(":")[2] or str(DEFAULT_SPHERE_SUBDIVISIONS)
        if not count.isdigit() or int(count) < 1:
            raise InputError(f"--mesh {spec}: expected sphere or sphere:N with N >= 1 subdivisions")
        from mesh2tex.limits import MAX_SPHERE_SUBDIVISIONS, check_size

        # before cube_sphere allocates
        check_size(f"--mesh {spec[:40]}: subdivisions", int(count), MAX_SPHERE_SUBDIVISIONS)
        vertices, faces = cube_sphere(int(count))
    elif spec.endswith(".npz"):
        from mesh2tex.geometry.prepared import PreparedShape

        shape = PreparedShape.load(spec)
        vertices, faces = shape.vertices[0], shape.quads[0]
    else:
        from mesh2tex.geometry.mesh_io import load_mesh

        vertices, faces = load_mesh(spec)
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if faces.shape[0] == 0:
        raise InputError(f"{spec}: the mesh has no faces")
    return vertices, faces


def unit_surface(
    vertices: np.ndarray, faces: np.ndarray, subdivide: int = 0, name: str = "mesh"
) -> tuple[np.ndarray, np.ndarray]:
    """A mesh of :func:`read_surface` with every face split into four ``subdivide`` times, then normalised
    to the unit ball: vertices (V', 3) float32, faces int64 (the inputs are not changed). InputError
    naming ``name`` for a mesh without extent."""
    check_array_shape(vertices, "unit_surface: vertices", ("V", 3))
    check_array_shape(faces, "unit_surface: faces", ("F", 4), ("F", 3))
    for _ in range(int(subdivide)):
        if faces.shape[1] == 4:
            vertices, faces = subdivide_quads(vertices, faces)
        else:
            import trimesh

            vertices, faces = trimesh.remesh.subdivide(vertices, faces)
    centre, radius = _centre_radius(vertices, name)
    return ((vertices - centre) / radius).astype(np.float32), faces.astype(np.int64)


def _centre_radius(vertices: np.ndarray, name: str) -> tuple[np.ndarray, float]:
    """The bounding box's centre (3,) and the farthest vertex's distance from it; InputError naming ``name`` without
    extent."""
    from mesh2tex.errors import InputError

    lo, hi = vertices.min(0), vertices.max(0)
    centre = (lo + hi) / 2
    radius = np.linalg.norm(vertices - centre, axis=1).max()
    if not np.isfinite(radius) or radius <= 0:
        raise InputError(f"{name}: the mesh has no extent (all vertices at one point, or non-finite positions)")
    return centre, radius


def unit_transform(vertices: np.ndarray, name: str = "mesh"):
    """The :class:`~mesh2tex.geometry.clean.Normalization` of :func:`unit_surface` (up to rounding): the
    bounding box's centre to the origin, the farthest vertex to radius 1 (splitting faces moves neither)."""
    check_array_shape(vertices, "unit_transform: vertices", ("V", 3))
    from mesh2tex.geometry.clean import Normalization

    centre, radius = _centre_radius(np.asarray(vertices, dtype=np.float64), name)
    return Normalization(centre=centre, scale=1.0 / radius)


def mean_edge_length(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Mean length of the face edges (each shared edge counted once per face)."""
    check_array_shape(vertices, "mean_edge_length: vertices", ("V", 3))
    check_array_shape(faces, "mean_edge_length: faces", ("F", 4), ("F", 3))
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    return float(np.linalg.norm(v[f] - v[np.roll(f, -1, axis=1)], axis=-1).mean())


def density_subdivisions(spacing: float, target: float, most: int = 3) -> int:
    """How many times to split a mesh's faces into four so that its mean edge length comes nearest to ``target``.

    Each split halves the edges, so the answer is the halving count whose spacing is nearest to the
    target on a log scale: a mesh stays as it is up to sqrt(2) times the target's spacing. A mesh
    finer than the target is never coarsened. ``target`` <= 0 (unknown) gives 0; at most ``most``.
    Both spacings must be measured in the same frame (:func:`load_surface`'s unit ball, the frame
    the automaton is rendered in, so equal spacing means equal cells per pixel).
    """
    if target <= 0 or spacing <= 0:
        return 0
    return int(min(max(round(np.log2(spacing / target)), 0), most))
