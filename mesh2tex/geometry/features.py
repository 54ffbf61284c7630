"""Geometric input features of quad faces (the encoder input of Mesh2Tex/Texturify) and NOC coordinates.

Each quad ``(v0, v1, v2, v3)`` is read as a bilinear patch ``X(s, t)`` over the unit square with
``X(0,0)=v0, X(1,0)=v1, X(1,1)=v2, X(0,1)=v3``; its normal field ``n(s, t)`` interpolates the
vertex normals the same way. At the patch centre:

    X_s = (v1 - v0 + v2 - v3) / 2,  X_t = (v3 - v0 + v2 - v1) / 2        (tangent vectors)
    first fundamental form   E = X_s.X_s,  F = X_s.X_t,  G = X_t.X_t
    second fundamental form  L = X_s.n_s,  M = (X_s.n_t + X_t.n_s) / 2,  N = X_t.n_t
    shape operator S = I^-1 II,  mean curvature H = trace(S) / 2,  Gaussian curvature K = det(S)

With outward normals a sphere of radius r has H = 1/r and K = 1/r^2 (convex is positive).

The stored features are made dimensionless with the quad's own size ``s = sqrt((E + G) / 2)`` (about
its edge length), so that they do not depend on the face count of the hierarchy, and the
curvature-like ones are compressed with ``asinh`` so that sharp creases (where K of a small quad
reaches 1e4 and more) do not swamp the network's input.

Which corner a quad's vertex list starts at, and its direction, is an accident of the remesher. A
cyclic shift of the list turns (X_s, X_t) into (X_t, -X_s), so E and G swap and F, M change sign
(L and N swap); the raw forms would make the input noisy from face to face. The stored features are
therefore invariants of that relabelling:

    fff_stretch                = |E - G| / (E + G)                             ([0, 1], 0: square-like)
    fff_shear                  = 2 |F| / (E + G)                               ([0, 1], 0: right angles)
    sff_sum                    = asinh((L + N) / (2 s))                        (normal curvature x s, mean)
    sff_diff                   = asinh(|L - N| / (2 s))
    sff_twist                  = asinh(|M| / s)
    mean_curvature             = asinh(H s)
    gaussian_curvature         = asinh(K s^2)

All of them, and the normal, are unchanged by a cyclic shift. Listing a quad in reverse swaps X_s
and X_t (E and G, L and N) and flips its orientation, which the normal, sff_sum and the mean
curvature carry; :func:`face_features` therefore first re-lists every quad in the coherent, outward
orientation of its connected part (:func:`mesh2tex.geometry.hierarchy.orient_coherently`, which
reads only the quads' edges and positions), so that the start and the direction of every quad's
list, and of the whole mesh's, change no feature.
"""

from __future__ import annotations

import numpy as np

from mesh2tex.checks import check_array_shape
from mesh2tex.geometry.hierarchy import orient_coherently

FEATURE_NAMES = [
    "normal_x",
    "normal_y",
    "normal_z",
    "fff_stretch",
    "fff_shear",
    "sff_sum",
    "sff_diff",
    "sff_twist",
    "mean_curvature",
    "gaussian_curvature",
]


def _normalize_rows(x: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(x, axis=-1, keepdims=True)
    return np.where(length > 1e-20, x / np.maximum(length, 1e-20), 0.0)


def quad_normals(vertices: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """(F, 3) float64 unit normal of each quad: the cross product of its diagonals (v2-v0) x (v3-v1)."""
    check_array_shape(vertices, "quad_normals: vertices", ("V", 3))
    check_array_shape(quads, "quad_normals: quads", ("F", 4))
    v = np.asarray(vertices, dtype=np.float64)[np.asarray(quads)]
    return _normalize_rows(np.cross(v[:, 2] - v[:, 0], v[:, 3] - v[:, 1]))


def vertex_normals(vertices: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """(V, 3) float64 unit vertex normals: the area-weighted sum of the quads around each vertex."""
    check_array_shape(vertices, "vertex_normals: vertices", ("V", 3))
    check_array_shape(quads, "vertex_normals: quads", ("F", 4))
    v = np.asarray(vertices, dtype=np.float64)
    q = np.asarray(quads, dtype=np.int64)
    weighted = np.cross(v[q[:, 2]] - v[q[:, 0]], v[q[:, 3]] - v[q[:, 1]]) / 2.0  # normal x area
    sums = np.zeros_like(v)
    for corner in range(4):
        np.add.at(sums, q[:, corner], weighted)
    return _normalize_rows(sums)


def fundamental_forms(vertices: np.ndarray, quads: np.ndarray) -> dict[str, np.ndarray]:
    """Raw per-face differential quantities at each quad's centre (see the module docstring).

    Args:
        vertices: (V, 3) float; quads: (F, 4) int, oriented outwards.
    Returns:
        dict of (F,) float64 arrays: E, F, G, L, M, N, H (mean curvature), K (Gaussian curvature);
        H and K are 0 on degenerate quads.
    """
    check_array_shape(vertices, "fundamental_forms: vertices", ("V", 3))
    check_array_shape(quads, "fundamental_forms: quads", ("F", 4))
    v = np.asarray(vertices, dtype=np.float64)
    q = np.asarray(quads, dtype=np.int64)
    p0, p1, p2, p3 = (v[q[:, i]] for i in range(4))
    vn = vertex_normals(v, q)
    n0, n1, n2, n3 = (vn[q[:, i]] for i in range(4))
    x_s, x_t = (p1 - p0 + p2 - p3) / 2.0, (p3 - p0 + p2 - p1) / 2.0
    n_s, n_t = (n1 - n0 + n2 - n3) / 2.0, (n3 - n0 + n2 - n1) / 2.0
    dot = lambda a, b: np.einsum("ij,ij->i", a, b)  # noqa: E731
    e, f, g = dot(x_s, x_s), dot(x_s, x_t), dot(x_t, x_t)
    l_, m, n = dot(x_s, n_s), (dot(x_s, n_t) + dot(x_t, n_s)) / 2.0, dot(x_t, n_t)
    det_first = e * g - f * f
    ok = det_first > 1e-14 * np.maximum(e * g, 1e-30)
    safe = np.where(ok, det_first, 1.0)
    return {
        "E": e,
        "F": f,
        "G": g,
        "L": l_,
        "M": m,
        "N": n,
        "H": np.where(ok, (e * n - 2.0 * f * m + g * l_) / (2.0 * safe), 0.0),
        "K": np.where(ok, (l_ * n - m * m) / safe, 0.0),
    }


def face_features(vertices: np.ndarray, quads: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Per-face geometric features: normals and the dimensionless, compressed, relabelling-invariant
    fundamental-form quantities and curvatures of the module docstring.

    Args:
        vertices: (V, 3) float, normalised frame; quads: (F, 4) int, each listed from any corner in
            either direction (re-oriented coherently and outwards here).
    Returns:
        (F, 10) float32 features, all finite, and their names (:data:`FEATURE_NAMES`).
    """
    check_array_shape(vertices, "face_features: vertices", ("V", 3))
    check_array_shape(quads, "face_features: quads", ("F", 4))
    quads = orient_coherently(vertices, quads)
    forms = fundamental_forms(vertices, quads)
    size_sq = np.maximum((forms["E"] + forms["G"]) / 2.0, 1e-30)
    size = np.sqrt(size_sq)
    trace_first = 2.0 * size_sq  # E + G
    features = np.stack(
        [
            *quad_normals(vertices, quads).T,
            np.abs(forms["E"] - forms["G"]) / trace_first,
            2.0 * np.abs(forms["F"]) / trace_first,
            np.arcsinh((forms["L"] + forms["N"]) / (2.0 * size)),
            np.arcsinh(np.abs(forms["L"] - forms["N"]) / (2.0 * size)),
            np.arcsinh(np.abs(forms["M"]) / size),
            np.arcsinh(forms["H"] * size),
            np.arcsinh(forms["K"] * size_sq),
        ],
        axis=1,
    )
    features = np.nan_to_num(features, nan=0.0, posinf=0.0, neginf=0.0)
    return features.astype(np.float32), list(FEATURE_NAMES)


def noc_coordinates(vertices: np.ndarray) -> np.ndarray:
    """(V, 3) float32 normalised object coordinates in [0, 1]^3: ``v + 0.5`` in the normalised frame.

    The normalised frame has its bounding-box centre at 0 and diagonal 1, so every coordinate
    lies in [-0.5, 0.5]; the same map for every shape keeps NOC comparable across a category.
    """
    check_array_shape(vertices, "noc_coordinates: vertices", ("V", 3))
    return np.clip(np.asarray(vertices, dtype=np.float64) + 0.5, 0.0, 1.0).astype(np.float32)
