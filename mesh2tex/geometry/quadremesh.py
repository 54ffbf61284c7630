"""Quad remeshing with QuadriFlow (the pyQuadriFlow package) and a hierarchy of face counts.

QuadriFlow turns a triangle mesh into a pure-quad mesh of about a requested face count. It fails at
times (an empty mesh, parts left out, a crash on a bad input), most often at the coarse levels of
shapes made of several parts. :func:`remesh_hierarchy` therefore tries, per level: other seeds, a
watertight re-make of the input, the finer level as input, and finally a coarsening of its own
(decimation, then each triangle split into three quads), so that every usable shape gets every level.

QuadriFlow runs in a forked child process where the platform allows it, so that a crash inside the
C++ library or a run past ``timeout`` ends one attempt, not the whole batch.
"""

from __future__ import annotations

import ctypes
import os
import pickle
import select
import signal
import time
from dataclasses import dataclass, field

import numpy as np

from mesh2tex.geometry.clean import decimate, resample_watertight, triangle_areas


class QuadRemeshError(RuntimeError):
    """QuadriFlow gave no usable quad mesh."""


_LIBRARY = None


def _library():
    """The QuadriFlow C library of pyQuadriFlow with typed entry points (loaded once)."""
    global _LIBRARY
    if _LIBRARY is None:
        # pyQuadriFlow's own wrapper copies every coordinate through Python lists; we only borrow
        # its loaded library and result struct and hand numpy buffers to the C function directly.
        from pyQuadriFlow.pyQuadriFlow import MESH_DATA, QuadriFlow_clib

        remesh = QuadriFlow_clib.remesh_quadriflow
        remesh.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_int,
                           ctypes.POINTER(ctypes.c_float * 3), ctypes.POINTER(ctypes.c_int * 3)] + [ctypes.c_bool] * 5
        remesh.restype = ctypes.POINTER(MESH_DATA)
        free = QuadriFlow_clib.free_mem
        free.argtypes = [ctypes.POINTER(MESH_DATA)]
        _LIBRARY = (remesh, free)
    return _LIBRARY


def _quadriflow_in_process(vertices: np.ndarray, faces: np.ndarray, target_faces: int, seed: int, flags: tuple) -> tuple[np.ndarray, np.ndarray]:
    remesh, free = _library()
    v = np.ascontiguousarray(vertices, dtype=np.float32)
    f = np.ascontiguousarray(faces, dtype=np.int32)
    result = remesh(int(target_faces), int(seed), len(v), len(f),
                    v.ctypes.data_as(ctypes.POINTER(ctypes.c_float * 3)), f.ctypes.data_as(ctypes.POINTER(ctypes.c_int * 3)), *flags)
    data = result.contents
    try:
        if data.has_error:
            raise QuadRemeshError(f"QuadriFlow internal error: {data.str_error.decode('ascii', 'replace')}")
        nv, nf = int(data.nn_verts), int(data.nn_faces)
        if nv == 0 or nf == 0:
            return np.zeros((0, 3)), np.zeros((0, 4), dtype=np.int64)
        out_v = np.ctypeslib.as_array(ctypes.cast(data.vertices, ctypes.POINTER(ctypes.c_float)), shape=(nv, 3)).astype(np.float64)
        out_f = np.ctypeslib.as_array(ctypes.cast(data.faces, ctypes.POINTER(ctypes.c_int)), shape=(nf, 4)).astype(np.int64)
        return out_v, out_f
    finally:
        free(result)


def _run_forked(function, args: tuple, timeout: float | None):
    """``function(*args)`` in a forked child; its result or exception comes back through a pipe."""
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # child: never returns into the caller's code
        os.close(read_fd)
        try:
            try:
                payload = ("ok", function(*args))
            except BaseException as error:  # noqa: BLE001 - everything goes back to the parent
                payload = ("error", f"{error.__class__.__name__}: {error}")
            data = pickle.dumps(payload, protocol=pickle.HIGHEST_PROTOCOL)
            with os.fdopen(write_fd, "wb") as pipe:
                pipe.write(data)
        finally:
            os._exit(0)
    os.close(write_fd)
    chunks, deadline = [], None if timeout is None else time.monotonic() + timeout
    timed_out = False
    with os.fdopen(read_fd, "rb") as pipe:
        while True:
            wait = None if deadline is None else max(0.0, deadline - time.monotonic())
            ready, _, _ = select.select([pipe], [], [], wait)
            if not ready:
                timed_out = True
                os.kill(pid, signal.SIGKILL)
                break
            chunk = os.read(pipe.fileno(), 1 << 20)
            if not chunk:
                break
            chunks.append(chunk)
    _, status = os.waitpid(pid, 0)
    if timed_out:
        raise QuadRemeshError(f"QuadriFlow ran past {timeout:.0f} s")
    if not chunks:
        reason = f"signal {os.WTERMSIG(status)}" if os.WIFSIGNALED(status) else f"exit status {os.WEXITSTATUS(status)}"
        raise QuadRemeshError(f"QuadriFlow crashed ({reason})")
    # the payload comes from our own forked child, never from a file or the network
    kind, value = pickle.loads(b"".join(chunks))
    if kind == "error":
        raise QuadRemeshError(value)
    return value


def quadriflow(vertices: np.ndarray, faces: np.ndarray, target_faces: int, seed: int = 0, *, preserve_sharp: bool = False,
               preserve_boundary: bool = False, adaptive_scale: bool = False, aggressive_sat: bool = False,
               minimum_cost_flow: bool = False, timeout: float | None = 300.0, isolate: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Quad-remesh a triangle mesh with QuadriFlow.

    Args:
        vertices: (V, 3) float; faces: (T, 3) int.
        target_faces: requested number of quads (QuadriFlow lands within about 10 %).
        seed: QuadriFlow's random seed.
        timeout: seconds before the attempt is abandoned (only when ``isolate``).
        isolate: run in a forked child process (POSIX only) so a crash cannot take the caller down.
    Returns:
        (N, 3) float64 vertices (unreferenced ones removed) and (M, 4) int64 quads; M may be 0.
    Raises:
        QuadRemeshError: QuadriFlow reported an error, crashed or ran past ``timeout``.
    """
    flags = (bool(preserve_sharp), bool(preserve_boundary), bool(adaptive_scale), bool(aggressive_sat), bool(minimum_cost_flow))
    args = (np.asarray(vertices), np.asarray(faces), int(target_faces), int(seed), flags)
    if isolate and hasattr(os, "fork"):
        out_v, out_q = _run_forked(_quadriflow_in_process, args, timeout)
    else:
        out_v, out_q = _quadriflow_in_process(*args)
    return remove_unreferenced(out_v, out_q)


def remove_unreferenced(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop vertices no face uses; returns (V', 3) and faces re-indexed (same shape and dtype int64)."""
    faces = np.asarray(faces, dtype=np.int64)
    if faces.size == 0:
        return np.zeros((0, 3)), faces.reshape(0, faces.shape[1] if faces.ndim == 2 else 4)
    used, inverse = np.unique(faces.reshape(-1), return_inverse=True)
    return np.asarray(vertices)[used], inverse.reshape(faces.shape).astype(np.int64)


def quads_to_triangles(quads: np.ndarray) -> np.ndarray:
    """(F, 4) quads -> (2F, 3) triangles: quad f gives (a, b, c) as 2f and (a, c, d) as 2f + 1."""
    quads = np.asarray(quads, dtype=np.int64)
    return np.stack([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]], axis=1).reshape(-1, 3)


def signed_volume(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """Signed volume enclosed by triangles (positive when a closed surface faces outwards)."""
    v = np.asarray(vertices, dtype=np.float64)[triangles]
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)


def triangles_to_quads(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split each triangle into three quads (corner, two edge midpoints, centroid); a pure-quad mesh.

    Args:
        vertices: (V, 3); triangles: (T, 3) int.
    Returns:
        (V + E + T, 3) float64 vertices and (3T, 4) int64 quads, oriented as the triangles.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64)
    t = len(triangles)
    edges = np.stack([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]], axis=1).reshape(-1, 2)
    unique_edges, edge_index = np.unique(np.sort(edges, axis=1), axis=0, return_inverse=True)
    edge_index = edge_index.reshape(t, 3) + len(vertices)  # midpoint vertex of edges (01, 12, 20)
    centroid_index = np.arange(t) + len(vertices) + len(unique_edges)
    new_vertices = np.concatenate([vertices, vertices[unique_edges].mean(axis=1), vertices[triangles].mean(axis=1)])
    quads = np.concatenate([
        np.stack([triangles[:, 0], edge_index[:, 0], centroid_index, edge_index[:, 2]], axis=1),
        np.stack([triangles[:, 1], edge_index[:, 1], centroid_index, edge_index[:, 0]], axis=1),
        np.stack([triangles[:, 2], edge_index[:, 2], centroid_index, edge_index[:, 1]], axis=1),
    ])
    return new_vertices, quads


def coarsen(vertices: np.ndarray, triangles: np.ndarray, target_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """Our own coarse quad mesh: decimate to about ``target_faces / 3`` triangles, split each into 3 quads.

    Returns (N, 3) float64 and (M, 4) int64 with M = 3 x the triangles the decimation reached.
    """
    v, t = decimate(vertices, triangles, max(1, int(round(target_faces / 3))))
    return triangles_to_quads(v, t)


def quad_mesh_problem(vertices: np.ndarray, quads: np.ndarray, target_faces: int, max_faces: int | None,
                      reference_area: float, reference_diagonal: float, min_ratio: float = 0.5, max_ratio: float = 2.0) -> str | None:
    """Why a remeshing result is unusable, or None when it is fine.

    Checks: not empty; face count within [min_ratio, max_ratio] x target and at most ``max_faces``
    (a coarser level must not have more faces than the finer one, or pooling cannot reach every
    coarse face); no quad with a repeated vertex; no edge shared by more than two quads; surface
    area and bounding-box diagonal within a factor of about two of the reference (no part left out).
    """
    n = len(quads)
    if n == 0:
        return "empty result"
    if n < min_ratio * target_faces or n > max_ratio * target_faces:
        return f"{n} faces, too far from the target {target_faces}"
    if max_faces is not None and n > max_faces:
        return f"{n} faces, more than the finer level's {max_faces}"
    q = np.asarray(quads)
    if np.any(np.sort(q, axis=1)[:, 1:] == np.sort(q, axis=1)[:, :-1]):
        return "quads with a repeated vertex"
    edges = np.sort(np.stack([q, np.roll(q, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    if counts.max() > 2:
        return "non-manifold edges"
    area = float(triangle_areas(vertices, quads_to_triangles(q)).sum())
    if not (0.4 * reference_area <= area <= 2.5 * reference_area):
        return f"surface area {area:.3g} far from the input's {reference_area:.3g} (parts lost or doubled)"
    diagonal = float(np.linalg.norm(np.ptp(np.asarray(vertices)[np.unique(q)], axis=0)))
    if diagonal < 0.75 * reference_diagonal:
        return "bounding box shrank: parts of the shape were left out"
    return None


def orient_outwards(vertices: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Quads reversed when their (triangulated) signed volume is negative, so normals face outwards."""
    if signed_volume(vertices, quads_to_triangles(quads)) < 0:
        return np.ascontiguousarray(quads[:, ::-1])
    return quads


@dataclass
class LevelResult:
    """One level of a hierarchy and how it was made."""

    vertices: np.ndarray  # (V, 3) float64
    quads: np.ndarray  # (F, 4) int64
    target: int
    method: str  # e.g. "quadriflow(input, seed=0)"
    attempts: list[dict] = field(default_factory=list)  # every try: method, faces, problem, seconds


def remesh_hierarchy(vertices: np.ndarray, faces: np.ndarray, face_counts: list[int], seed: int = 0,
                     extra_seeds: int = 1, timeout: float | None = 300.0, isolate: bool = True) -> list[LevelResult]:
    """Quad meshes of decreasing face counts for one triangle mesh (level 0 the finest).

    Per level, in order until one passes :func:`quad_mesh_problem`: QuadriFlow on the input with
    ``seed`` then ``extra_seeds`` other seeds; QuadriFlow on a watertight re-make of the input (asking for the
    target, then twice the target); for
    coarse levels QuadriFlow on the finer level; our own :func:`coarsen` of the finer level (or of
    the re-made input at level 0); and, last, a copy of the finer level so that pooling still holds.

    Args:
        vertices: (V, 3) float, normalised; faces: (T, 3) int, repaired (see clean.clean_mesh).
        face_counts: targets, finest first, e.g. [6144, 1536, 384, 96, 24].
    Returns:
        one :class:`LevelResult` per target.
    Raises:
        QuadRemeshError: not even the finest level could be made.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    reference_area = float(triangle_areas(vertices, faces).sum())
    reference_diagonal = float(np.linalg.norm(np.ptp(vertices[np.unique(faces)], axis=0)))
    watertight: tuple[np.ndarray, np.ndarray] | None = None

    def remade_input():
        nonlocal watertight
        if watertight is None:
            watertight = resample_watertight(vertices, faces)
        return watertight

    levels: list[LevelResult] = []
    for level, target in enumerate(face_counts):
        finer = levels[-1] if levels else None
        max_faces = len(finer.quads) if finer is not None else None
        attempts: list[dict] = []

        def candidates():
            for s in range(seed, seed + 1 + extra_seeds):
                yield f"quadriflow(input, seed={s})", lambda s=s: quadriflow(vertices, faces, target, s, timeout=timeout, isolate=isolate)
            yield f"quadriflow(watertight input, seed={seed})", lambda: quadriflow(*remade_input(), target, seed, timeout=timeout, isolate=isolate)
            # at small counts QuadriFlow often undershoots (several parts, few faces each): ask for more
            yield f"quadriflow(watertight input, 2x target, seed={seed})", lambda: quadriflow(*remade_input(), 2 * target, seed, timeout=timeout, isolate=isolate)
            if finer is not None:
                yield f"quadriflow(level {level - 1}, seed={seed})", lambda: quadriflow(finer.vertices, quads_to_triangles(finer.quads), target, seed, timeout=timeout, isolate=isolate)
                yield f"coarsen(level {level - 1})", lambda: coarsen(finer.vertices, quads_to_triangles(finer.quads), target)
            else:
                yield "coarsen(watertight input)", lambda: coarsen(*remade_input(), target)

        chosen = None
        for method, make in candidates():
            start = time.perf_counter()
            try:
                out_v, out_q = make()
                # our own coarsening may miss the count on many-part shapes; it only has to stay below the finer level
                loose = method.startswith("coarsen")
                problem = quad_mesh_problem(out_v, out_q, target, max_faces, reference_area, reference_diagonal,
                                            min_ratio=0.0 if loose else 0.5, max_ratio=np.inf if loose else 2.0)
            except QuadRemeshError as error:
                out_v, out_q, problem = None, None, str(error)
            attempts.append({"method": method, "faces": 0 if out_q is None else int(len(out_q)), "problem": problem,
                             "seconds": round(time.perf_counter() - start, 3)})
            if problem is None:
                chosen = LevelResult(out_v, orient_outwards(out_v, out_q), target, method, attempts)
                break
        if chosen is None:
            if finer is None:
                reasons = "; ".join(f"{a['method']}: {a['problem']}" for a in attempts)
                raise QuadRemeshError(f"no quad mesh at {target} faces ({reasons})")
            chosen = LevelResult(finer.vertices.copy(), finer.quads.copy(), target, f"copy of level {level - 1}", attempts)
        levels.append(chosen)
    return levels
