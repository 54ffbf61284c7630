"""QuadriFlow (the pyQuadriFlow package's C library) called on NumPy buffers, in a forked child process
where the platform allows it, so that a crash inside the C++ library, a run past its time or past its
memory ends one attempt with :class:`QuadRemeshError`, not the caller. :mod:`mesh2tex.geometry.quadremesh`
builds the hierarchy of levels on it."""

from __future__ import annotations

import ctypes
import os
import pickle
import select
import signal
import time

import numpy as np


class QuadRemeshError(RuntimeError):
    """QuadriFlow gave no usable quad mesh."""


class BudgetExceeded(QuadRemeshError):
    """A shape's preparation ran past its time budget (no further attempt is made)."""


_LIBRARY = None


def _library():
    """The QuadriFlow C library of pyQuadriFlow with typed entry points (loaded once)."""
    global _LIBRARY
    if _LIBRARY is None:
        # pyQuadriFlow's own wrapper copies every coordinate through Python lists; we only borrow
        # its loaded library and result struct and hand numpy buffers to the C function directly.
        from pyQuadriFlow.pyQuadriFlow import MESH_DATA, QuadriFlow_clib

        remesh = QuadriFlow_clib.remesh_quadriflow
        remesh.argtypes = [
            ctypes.c_int,
            ctypes.c_int,
            ctypes.c_int,
            ctypes.c_int,
            ctypes.POINTER(ctypes.c_float * 3),
            ctypes.POINTER(ctypes.c_int * 3),
        ] + [ctypes.c_bool] * 5
        remesh.restype = ctypes.POINTER(MESH_DATA)
        free = QuadriFlow_clib.free_mem
        free.argtypes = [ctypes.POINTER(MESH_DATA)]
        _LIBRARY = (remesh, free)
    return _LIBRARY


def _quadriflow_in_process(
    vertices: np.ndarray, faces: np.ndarray, target_faces: int, seed: int, flags: tuple
) -> tuple[np.ndarray, np.ndarray]:
    remesh, free = _library()
    v = np.ascontiguousarray(vertices, dtype=np.float32)
    f = np.ascontiguousarray(faces, dtype=np.int32)
    result = remesh(
        int(target_faces),
        int(seed),
        len(v),
        len(f),
        v.ctypes.data_as(ctypes.POINTER(ctypes.c_float * 3)),
        f.ctypes.data_as(ctypes.POINTER(ctypes.c_int * 3)),
        *flags,
    )
    data = result.contents
    try:
        if data.has_error:
            raise QuadRemeshError(f"QuadriFlow internal error: {data.str_error.decode('ascii', 'replace')}")
        nv, nf = int(data.nn_verts), int(data.nn_faces)
        if nv == 0 or nf == 0:
            return np.zeros((0, 3)), np.zeros((0, 4), dtype=np.int64)
        out_v = np.ctypeslib.as_array(ctypes.cast(data.vertices, ctypes.POINTER(ctypes.c_float)), shape=(nv, 3)).astype(
            np.float64
        )
        out_f = np.ctypeslib.as_array(ctypes.cast(data.faces, ctypes.POINTER(ctypes.c_int)), shape=(nf, 4)).astype(
            np.int64
        )
        return out_v, out_f
    finally:
        free(result)


def _run_forked(function, args: tuple, timeout: float | None, memory_gb: float | None = None):
    """``function(*args)`` in a forked child (its address space limited to ``memory_gb`` GiB when given);
    its result or exception comes back through a pipe."""
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # child: never returns into the caller's code
        os.close(read_fd)
        try:
            # the C library prints debugging lines of its own ("wrong init 198 207!"); what the caller needs, an
            # error's message included, comes back through the pipe, and a crash is named by the parent
            quiet = os.open(os.devnull, os.O_WRONLY)
            os.dup2(quiet, 1)
            os.dup2(quiet, 2)
            try:
                if memory_gb is not None:
                    import resource

                    limit = int(memory_gb * 2**30)
                    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
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
    beyond = f" (run within a memory budget of {memory_gb:g} GiB)" if memory_gb is not None else ""
    if not chunks:
        reason = f"signal {os.WTERMSIG(status)}" if os.WIFSIGNALED(status) else f"exit status {os.WEXITSTATUS(status)}"
        raise QuadRemeshError(f"QuadriFlow crashed ({reason}){beyond}")
    # the payload comes from our own forked child, never from a file or the network
    kind, value = pickle.loads(b"".join(chunks))
    if kind == "error":
        raise QuadRemeshError(value + beyond)
    return value


def quadriflow(
    vertices: np.ndarray,
    faces: np.ndarray,
    target_faces: int,
    seed: int = 0,
    *,
    preserve_sharp: bool = False,
    preserve_boundary: bool = False,
    adaptive_scale: bool = False,
    aggressive_sat: bool = False,
    minimum_cost_flow: bool = False,
    timeout: float | None = 300.0,
    isolate: bool = True,
    memory_gb: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Quad-remesh a triangle mesh with QuadriFlow.

    Args:
        vertices: (V, 3) float; faces: (T, 3) int.
        target_faces: requested number of quads (QuadriFlow lands within about 10 %).
        seed: QuadriFlow's random seed.
        timeout: seconds before the attempt is abandoned (only when ``isolate``).
        isolate: run in a forked child process (POSIX only) so a crash cannot take the caller down.
        memory_gb: address-space limit of that child, GiB (only when ``isolate``).
    Returns:
        (N, 3) float64 vertices (unreferenced ones removed) and (M, 4) int64 quads; M may be 0.
    Raises:
        QuadRemeshError: QuadriFlow reported an error, crashed or ran past ``timeout``.
    """
    flags = (
        bool(preserve_sharp),
        bool(preserve_boundary),
        bool(adaptive_scale),
        bool(aggressive_sat),
        bool(minimum_cost_flow),
    )
    args = (np.asarray(vertices), np.asarray(faces), int(target_faces), int(seed), flags)
    if isolate and hasattr(os, "fork"):
        out_v, out_q = _run_forked(_quadriflow_in_process, args, timeout, memory_gb)
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
