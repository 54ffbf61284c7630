"""Face neighbourhoods and pooling maps of quad-mesh hierarchies.

A 3x3 neighbourhood of a quad face ``f = (v0, v1, v2, v3)`` is ``f`` itself followed by its 8 ring
faces in the rotational order of its vertices, edge and corner neighbours alternating:

    E_k, C_k, E_{k+1}, C_{k+1}, E_{k+2}, C_{k+2}, E_{k+3}, C_{k+3}      (indices mod 4)

where ``E_i`` is the face across edge ``(v_i, v_{i+1})`` and ``C_i`` the face diagonally across
vertex ``v_{i+1}`` (it shares that vertex only). The start ``k`` is the edge whose midpoint is
smallest in x, then y, then z (the deterministic rule of Texturify, applied to edge midpoints so
that it does not depend on which neighbours exist). A neighbour is -1 when it does not exist: a
boundary or non-manifold edge, or a corner at a vertex with other than four faces around it.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from mesh2tex.checks import check_array_shape


def edge_neighbors(quads: np.ndarray) -> np.ndarray:
    """(F, 4) int64: the face across edge ``(v_i, v_{i+1})`` of each quad, -1 on boundary or non-manifold edges."""
    check_array_shape(quads, "edge_neighbors: quads", ("F", 4))
    return polygon_edge_neighbors(quads)


def polygon_edge_neighbors(faces: np.ndarray) -> np.ndarray:
    """(F, K) int64: the face across edge ``(v_i, v_{i+1 mod K})`` of each K-gon (quads, triangles), -1 on
    boundary or non-manifold edges and where a face meets itself."""
    check_array_shape(faces, "polygon_edge_neighbors: faces", ("F", "K"))
    faces = np.asarray(faces, dtype=np.int64)
    f, k = faces.shape
    edges = np.sort(np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    _, edge_id, counts = np.unique(edges, axis=0, return_inverse=True, return_counts=True)
    edge_id = edge_id.reshape(-1)
    slot = np.arange(k * f)
    order = np.argsort(edge_id, kind="stable")
    sorted_ids = edge_id[order]
    first = np.searchsorted(sorted_ids, sorted_ids)  # first slot of each edge in sorted order
    manifold = counts[edge_id] == 2
    # for a manifold edge the partner is the other of the two slots sharing the edge id
    partner_sorted = np.where(np.arange(k * f) == first, np.arange(k * f) + 1, first)
    partner = np.empty(k * f, dtype=np.int64)
    partner[order] = order[np.clip(partner_sorted, 0, k * f - 1)]
    result = np.where(manifold, partner // k, -1)
    result[result == slot // k] = -1  # a face folded onto itself is no neighbour
    return result.reshape(f, k)


def face_neighborhoods(vertices: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """The 3x3 neighbourhood of every quad face (see the module docstring for the order).

    Args:
        vertices: (V, 3) float; quads: (F, 4) int, consistently oriented.
    Returns:
        (F, 9) int64: column 0 the face itself, columns 1..8 its ring, -1 where missing.
    """
    check_array_shape(vertices, "face_neighborhoods: vertices", ("V", 3))
    check_array_shape(quads, "face_neighborhoods: quads", ("F", 4))
    vertices = np.asarray(vertices, dtype=np.float64)
    quads = np.asarray(quads, dtype=np.int64)
    f = len(quads)
    edge_nb = edge_neighbors(quads)  # (F, 4)
    faces = np.arange(f)

    # corner neighbour at vertex v_{i+1}: walk across edge i, then across the other edge of that
    # face at the vertex; walk across edge i+1 the same way; both walks must meet in one face.
    corner = np.full((f, 4), -1, dtype=np.int64)
    for i in range(4):
        vertex = quads[:, (i + 1) % 4]
        walks = []
        for edge in (i, (i + 1) % 4):
            nb = edge_nb[:, edge]
            valid = nb >= 0
            nb_safe = np.where(valid, nb, 0)
            position = np.argmax(quads[nb_safe] == vertex[:, None], axis=1)  # where the vertex sits in the neighbour
            has_vertex = (quads[nb_safe] == vertex[:, None]).any(axis=1)
            before = edge_nb[nb_safe, (position - 1) % 4]  # across edge (p-1, p) of the neighbour
            after = edge_nb[nb_safe, position]  # across edge (p, p+1) of the neighbour
            other = np.where(before == faces, after, np.where(after == faces, before, -1))
            walks.append(np.where(valid & has_vertex, other, -1))
        meet = np.where(walks[0] == walks[1], walks[0], -1)
        meet[(meet == faces) | (meet == edge_nb[:, i]) | (meet == edge_nb[:, (i + 1) % 4])] = -1
        # the corner face must share exactly one vertex with the centre face
        safe = np.where(meet >= 0, meet, 0)
        shared = (quads[safe][:, :, None] == quads[:, None, :]).any(axis=2).sum(axis=1)
        corner[:, i] = np.where((meet >= 0) & (shared == 1), meet, -1)

    ring = np.stack([edge_nb, corner], axis=2).reshape(f, 8)  # E0 C0 E1 C1 E2 C2 E3 C3
    # start at the edge with the smallest midpoint (x, then y, then z); rounding makes ties exact
    midpoints = np.round((vertices[quads] + vertices[np.roll(quads, -1, axis=1)]) / 2.0, 6).reshape(-1, 3)
    # face is the primary key
    order = np.lexsort((midpoints[:, 2], midpoints[:, 1], midpoints[:, 0], np.repeat(faces, 4)))
    start = order[0::4] % 4
    columns = (2 * start[:, None] + np.arange(8)[None, :]) % 8
    ordered = np.take_along_axis(ring, columns, axis=1)
    return np.concatenate([faces[:, None], ordered], axis=1)


def face_centres(vertices: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """(F, 3) float64 mean of each quad's four vertices."""
    check_array_shape(vertices, "face_centres: vertices", ("V", 3))
    check_array_shape(quads, "face_centres: quads", ("F", 4))
    return np.asarray(vertices, dtype=np.float64)[np.asarray(quads)].mean(axis=1)


def pooling_map(
    fine_vertices: np.ndarray,
    fine_quads: np.ndarray,
    coarse_vertices: np.ndarray,
    coarse_quads: np.ndarray,
    candidates: int = 16,
) -> np.ndarray:
    """Map every fine face to one coarse face so that every coarse face receives at least one.

    Each fine face first goes to the coarse face with the nearest centre. A coarse face left
    without any then takes, among the fine faces nearest to it, the closest one whose current
    coarse face keeps at least one other; this repeats until every coarse face is covered.

    Args:
        fine_vertices: (V_f, 3); fine_quads: (F_f, 4); coarse_vertices: (V_c, 3); coarse_quads: (F_c, 4).
    Returns:
        (F_f,) int64 indices into the coarse faces.
    Raises:
        ValueError: the coarse level has more faces than the fine one.
    """
    check_array_shape(fine_vertices, "pooling_map: fine_vertices", ("V_f", 3))
    check_array_shape(fine_quads, "pooling_map: fine_quads", ("F_f", 4))
    check_array_shape(coarse_vertices, "pooling_map: coarse_vertices", ("V_c", 3))
    check_array_shape(coarse_quads, "pooling_map: coarse_quads", ("F_c", 4))
    fine_centres = face_centres(fine_vertices, fine_quads)
    coarse_centres = face_centres(coarse_vertices, coarse_quads)
    n_fine, n_coarse = len(fine_centres), len(coarse_centres)
    if n_coarse > n_fine:
        raise ValueError(f"the coarse level has more faces ({n_coarse}) than the fine one ({n_fine})")
    _, assignment = cKDTree(coarse_centres).query(fine_centres, k=1)
    assignment = np.asarray(assignment, dtype=np.int64)
    counts = np.bincount(assignment, minlength=n_coarse)
    fine_tree = cKDTree(fine_centres)
    for coarse in np.flatnonzero(counts == 0):
        k = min(candidates, n_fine)
        while True:
            _, nearest = fine_tree.query(coarse_centres[coarse], k=k)
            nearest = np.atleast_1d(nearest)
            movable = [i for i in nearest if counts[assignment[i]] > 1]
            if movable or k == n_fine:
                break
            k = min(4 * k, n_fine)
        if not movable:  # every fine face is alone on its coarse face: impossible when n_coarse <= n_fine
            raise ValueError("no fine face can be moved to an empty coarse face")
        chosen = movable[0]
        counts[assignment[chosen]] -= 1
        assignment[chosen] = coarse
        counts[coarse] += 1
    return assignment


def orient_coherently(vertices: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Quads re-listed (reversed where needed) so that each connected part is coherently oriented, outwards.

    Two quads across a manifold edge agree when they traverse it in opposite directions; a
    breadth-first walk over those edges reverses the quads that disagree with the part's first quad,
    then the whole part is reversed if it encloses negative volume (``(1/3) sum_f (c_f - c) . a_f``
    with ``c_f`` the quad's centre, ``a_f = (v2 - v0) x (v3 - v1) / 2`` its area vector and ``c`` the
    part's centre). Nothing here depends on where a quad's vertex list starts or on its direction,
    so any listing of the same quads gives the same orientation. A part that cannot be oriented (a
    Moebius band) keeps the orientation the walk gives it.

    Args:
        vertices: (V, 3) float; quads: (F, 4) int.
    Returns:
        (F, 4) int64: every row the input row or its reverse.
    """
    check_array_shape(vertices, "orient_coherently: vertices", ("V", 3))
    check_array_shape(quads, "orient_coherently: quads", ("F", 4))
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order, connected_components

    v = np.asarray(vertices, dtype=np.float64)
    q = np.asarray(quads, dtype=np.int64)
    f = len(q)
    if f == 0:
        return q.copy()
    start, end = q.reshape(-1), np.roll(q, -1, axis=1).reshape(-1)
    face = np.repeat(np.arange(f), 4)
    proper = start != end
    start, end, face = start[proper], end[proper], face[proper]
    key = np.minimum(start, end) * (int(q.max()) + 1) + np.maximum(start, end)
    forward = start < end
    order = np.argsort(key, kind="stable")
    key, forward, face = key[order], forward[order], face[order]
    _, first, counts = np.unique(key, return_index=True, return_counts=True)
    pairs = first[counts == 2]
    a, b = face[pairs], face[pairs + 1]
    keep = a != b
    a, b = a[keep], b[keep]
    disagree = (forward[pairs] == forward[pairs + 1])[keep]  # same direction: one of the two must flip
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(f, f)).tocsr()
    n_parts, part = connected_components(graph, directed=False)
    flip_of_pair = {}
    for x, y, d in zip(a.tolist(), b.tolist(), disagree.tolist()):
        flip_of_pair[(x, y)] = flip_of_pair[(y, x)] = d
    flip = np.zeros(f, dtype=bool)
    for p in range(n_parts):
        root = int(np.flatnonzero(part == p)[0])
        visit, parent = breadth_first_order(graph, root, directed=False, return_predecessors=True)
        for node in visit[1:].tolist():
            up = int(parent[node])
            flip[node] = flip[up] ^ flip_of_pair[(node, up)]
    oriented = np.where(flip[:, None], q[:, ::-1], q)
    p = v[oriented]
    centres = p.mean(axis=1)
    area = np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 1]) / 2.0
    weight = np.linalg.norm(area, axis=1)
    part_centre = np.stack(
        [np.bincount(part, weights=weight * centres[:, k], minlength=n_parts) for k in range(3)], axis=1
    )
    part_centre /= np.maximum(np.bincount(part, weights=weight, minlength=n_parts), 1e-30)[:, None]
    volume = np.bincount(part, weights=np.einsum("ij,ij->i", centres - part_centre[part], area), minlength=n_parts)
    reverse = volume[part] < 0
    return np.ascontiguousarray(np.where(reverse[:, None], oriented[:, ::-1], oriented))
