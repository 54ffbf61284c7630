"""One function that turns a triangle mesh into a :class:`PreparedShape` (in memory, no files)."""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial import cKDTree

from mesh2tex.checks import check_array_shape
from mesh2tex.errors import InputError
from mesh2tex.geometry.clean import Normalization, clean_mesh, decimate, normalize
from mesh2tex.geometry.features import face_features, noc_coordinates
from mesh2tex.geometry.hierarchy import face_neighborhoods, pooling_map
from mesh2tex.geometry.levelset import surface_samples
from mesh2tex.geometry.prepared import PreparedShape, quads_to_triangles
from mesh2tex.geometry.quadremesh import Budget, QuadRemeshError, remesh_hierarchy

# QuadriFlow's run time grows with the input; more triangles than this add nothing at 6144 quads
MAX_INPUT_TRIANGLES = 100_000
# A finest level is too coarse for its shape when more than 1 % of the input's surface lies farther than
# 5 % of the bounding-box diagonal from it: a part (a seat, a leg) was lost or melted into a blob.
DEVIATION_QUANTILE = 0.99
DEVIATION_LIMIT = 0.05


def level_face_counts(face_count: int, levels: int) -> list[int]:
    """Target quad counts, finest first, divided by 4 per level: 6144, 5 -> [6144, 1536, 384, 96, 24]."""
    if face_count < 1 or levels < 1:
        raise InputError(f"face count ({face_count}) and levels ({levels}) must be positive")
    from mesh2tex.limits import MAX_FACES, MAX_LEVELS, check_size

    check_size("face count", face_count, MAX_FACES)
    check_size("levels", levels, MAX_LEVELS)
    counts = [int(round(face_count / 4**level)) for level in range(levels)]
    if counts[-1] < 4:
        raise InputError(f"{levels} levels from {face_count} faces leave fewer than 4 faces at the coarsest level")
    return counts


def prepare_shape(
    vertices: np.ndarray,
    faces: np.ndarray,
    face_count: int = 6144,
    levels: int = 5,
    seed: int = 0,
    source: str = "",
    timeout: float | None = 300.0,
    max_seconds: float | None = None,
    max_memory_gb: float | None = None,
    up: str = "y",
) -> PreparedShape:
    """Repair, normalise and quad-remesh a mesh into a hierarchy with neighbourhoods, pooling and features.

    Args:
        vertices: (V, 3) float, any frame; faces: (T, 3) int (e.g. from ``mesh_io.load_mesh``).
        face_count: quads of the finest level; each coarser level has a quarter as many.
        levels: number of levels (level 0 the finest).
        seed: QuadriFlow seed (other seeds are tried on failure).
        source: recorded in the metadata (e.g. the input path).
        up: the source file's up axis, recorded in the metadata: 'z' when ``vertices`` were turned y-up
            from a z-up file (:meth:`mesh2tex.geometry.mesh_io.UserMesh.working_vertices`), else 'y'.
        timeout: seconds per QuadriFlow attempt.
        max_seconds: the shape's time budget (cleaning and every remeshing attempt); past it the
            preparation stops with that reason. None: no limit.
        max_memory_gb: address-space limit of each QuadriFlow process, GiB. None: no limit.
    Returns:
        a :class:`PreparedShape` in the normalised frame (bbox centre 0, diagonal 1); its metadata
        holds the transform from the input frame, the method used per level, seconds, seeds and
        ``coarseness`` (:func:`coarseness_check`; a too coarse hierarchy also gets a warning).
    Raises:
        InputError: the mesh is unusable (no area, no quad mesh possible), or its budget was spent, with the reason.
    """
    check_array_shape(vertices, "prepare_shape: vertices", ("V", 3))
    check_array_shape(faces, "prepare_shape: faces", ("T", 3))
    start = time.perf_counter()
    budget = Budget(seconds=max_seconds, memory_gb=max_memory_gb)
    targets = level_face_counts(face_count, levels)
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    clean_v, clean_f, transform = _clean_input(vertices, faces)
    seconds_clean = time.perf_counter() - start
    try:
        results = remesh_hierarchy(clean_v, clean_f, targets, seed=seed, timeout=timeout, budget=budget)
    except QuadRemeshError as error:
        raise InputError(str(error)) from None
    seconds_remesh = time.perf_counter() - start - seconds_clean

    level_vertices = [r.vertices for r in results]
    level_quads = [r.quads for r in results]
    coarseness = coarseness_check(clean_v, clean_f, level_vertices[0], level_quads[0], face_count)
    record = _levels_metadata(results)
    metadata = {
        "source": str(source),
        "up": str(up),
        "transform": transform.to_json(),
        "input": {"vertices": int(len(vertices)), "triangles": int(len(faces)), "cleaned_triangles": int(len(clean_f))},
        "targets": targets,
        "face_counts": record["face_counts"],
        "levels": record["levels"],
        "warnings": record["warnings"] + coarseness_warning(coarseness),
        "coarseness": coarseness,
        "seed": int(seed),
        "seeds": record["seeds"],
        "seconds": {
            "clean": round(seconds_clean, 3),
            "remesh": round(seconds_remesh, 3),
            "total": round(time.perf_counter() - start, 3),
        },
    }
    return _hierarchy(level_vertices, level_quads, metadata)


def _hierarchy(level_vertices: list[np.ndarray], level_quads: list[np.ndarray], metadata: dict) -> PreparedShape:
    """The prepared shape of quad levels (vertices (V_l, 3), quads (F_l, 4), finest first): their
    neighbourhoods, the pooling maps between consecutive levels, the finest level's features and NOC."""
    neighbors = [face_neighborhoods(v, q) for v, q in zip(level_vertices, level_quads)]
    pool = [
        pooling_map(level_vertices[l], level_quads[l], level_vertices[l + 1], level_quads[l + 1])
        for l in range(len(level_quads) - 1)
    ]
    features, names = face_features(level_vertices[0], level_quads[0])
    return PreparedShape(
        vertices=[v.astype(np.float32) for v in level_vertices],
        quads=[q.astype(np.int64) for q in level_quads],
        neighbors=neighbors,
        pool=pool,
        face_features=features,
        feature_names=names,
        noc=noc_coordinates(level_vertices[0]),
        metadata=metadata,
    )


def _clean_input(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, Normalization]:
    """The used vertices normalised (bbox centre 0, diagonal 1), repaired and decimated to at most
    :data:`MAX_INPUT_TRIANGLES`: (vertices (V', 3), triangles (T', 3), the transform from the input frame)."""
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise InputError("the mesh has no triangles")
    used = np.unique(faces)
    normalized, transform = normalize(vertices[used])
    remapped = np.searchsorted(used, faces)
    clean_v, clean_f = clean_mesh(normalized, remapped)
    if len(clean_f) > MAX_INPUT_TRIANGLES:
        clean_v, clean_f = decimate(clean_v, clean_f, MAX_INPUT_TRIANGLES)
    return clean_v, clean_f, transform


def _levels_metadata(results: list) -> dict:
    """The per-level record of a remeshed hierarchy (``face_counts``, ``levels``, the levels' ``warnings``
    and the QuadriFlow ``seeds`` tried), from :func:`remesh_hierarchy`'s results."""
    return {
        "face_counts": [int(len(r.quads)) for r in results],
        "levels": [
            {
                "target": r.target,
                "faces": int(len(r.quads)),
                "ratio": None if l == 0 else round(len(results[l - 1].quads) / len(r.quads), 3),
                "method": r.method,
                "warnings": r.warnings,
                "seconds": r.seconds,
                "attempts": r.attempts,
            }
            for l, r in enumerate(results)
        ],
        "warnings": [f"level {l}: {w}" for l, r in enumerate(results) for w in r.warnings],
        "seeds": sorted(
            {
                int(a["method"].split("seed=")[1].rstrip(")"))
                for r in results
                for a in r.attempts
                if "seed=" in a["method"]
            }
        ),
    }


def prepare_user_mesh(mesh, face_count: int = 6144, levels: int = 5, seed: int = 0, **budgets) -> PreparedShape:
    """:func:`prepare_shape` of a :class:`~mesh2tex.geometry.mesh_io.UserMesh`, turned y-up first; its
    errors name the file. ``budgets``: ``timeout``, ``max_seconds``, ``max_memory_gb``."""
    try:
        return prepare_shape(
            mesh.working_vertices(),
            mesh.faces,
            face_count=face_count,
            levels=levels,
            seed=seed,
            source=mesh.path,
            up=mesh.up,
            **budgets,
        )
    except InputError as error:
        raise (error if str(error).startswith(mesh.path) else InputError(f"{mesh.path}: {error}")) from None


def surface_deviation(
    vertices: np.ndarray,
    triangles: np.ndarray,
    quad_vertices: np.ndarray,
    quads: np.ndarray,
    quantile: float = DEVIATION_QUANTILE,
    max_points: int = 20_000,
) -> float:
    """The distance within which ``quantile`` of the input's surface lies from the quad mesh (in the
    units of the vertices: bounding-box diagonals in the normalised frame).

    The input surface is sampled about every 0.01 (at most ``max_points`` points, a fixed subset) and
    the quad mesh's triangles every 0.004; distances are point to nearest sample, so they read at most
    about 0.003 high. vertices: (V, 3), triangles: (T, 3) the input; quad_vertices: (V', 3), quads: (F, 4).
    """
    check_array_shape(vertices, "surface_deviation: vertices", ("V", 3))
    check_array_shape(triangles, "surface_deviation: triangles", ("T", 3))
    check_array_shape(quad_vertices, "surface_deviation: quad_vertices", ("V'", 3))
    check_array_shape(quads, "surface_deviation: quads", ("F", 4))
    diagonal = float(np.linalg.norm(np.ptp(np.asarray(vertices, dtype=np.float64), axis=0))) or 1.0
    probes = surface_samples(vertices, triangles, 0.01 * diagonal)
    if len(probes) > max_points:
        probes = probes[np.random.default_rng(0).choice(len(probes), max_points, replace=False)]
    target = surface_samples(
        np.asarray(quad_vertices, dtype=np.float64), quads_to_triangles(np.asarray(quads)), 0.004 * diagonal
    )
    distance, _ = cKDTree(target).query(probes, k=1)
    return float(np.quantile(distance, quantile))


def coarseness_check(
    vertices: np.ndarray, triangles: np.ndarray, quad_vertices: np.ndarray, quads: np.ndarray, face_count: int
) -> dict:
    """Whether a finest level of ``face_count`` requested quads keeps the shape's parts.

    ``deviation``: :func:`surface_deviation` of the input (normalised, bbox diagonal 1) from the
    finest level, in bbox diagonals; ``too_coarse`` when it exceeds :data:`DEVIATION_LIMIT`. Then
    ``suggested_faces`` is the smallest ``face_count * 4**k`` at which the deviation, taken to shrink
    in proportion to the quad edge (halving per factor 4; measured on the synthetic chairs, it falls
    faster than that once the lost parts come back), is within the limit; None when not too coarse.
    """
    check_array_shape(vertices, "coarseness_check: vertices", ("V", 3))
    check_array_shape(triangles, "coarseness_check: triangles", ("T", 3))
    check_array_shape(quad_vertices, "coarseness_check: quad_vertices", ("V'", 3))
    check_array_shape(quads, "coarseness_check: quads", ("F", 4))
    deviation = surface_deviation(vertices, triangles, quad_vertices, quads)
    too_coarse = deviation > DEVIATION_LIMIT
    suggested = None
    if too_coarse:
        k = max(1, int(np.ceil(np.log2(deviation / DEVIATION_LIMIT))))
        suggested = int(face_count * 4**k)
    return {
        "deviation": round(deviation, 4),
        "quantile": DEVIATION_QUANTILE,
        "limit": DEVIATION_LIMIT,
        "requested_faces": int(face_count),
        "faces": int(len(quads)),
        "too_coarse": bool(too_coarse),
        "suggested_faces": suggested,
    }


def coarseness_warning(coarseness: dict) -> list[str]:
    """[] or the one-line warning of a too coarse hierarchy (:func:`coarseness_check`'s record)."""
    if not coarseness.get("too_coarse"):
        return []
    share = round(100 * (1 - coarseness["quantile"]))
    return [
        f"{coarseness['requested_faces']} faces are too coarse for this shape: {share} % of its surface lies more than "
        f"{100 * coarseness['deviation']:.0f} % of its size from the {coarseness['faces']}-quad mesh (parts lost); "
        f"suggested: at least {coarseness['suggested_faces']} faces"
    ]
