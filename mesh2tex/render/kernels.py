"""The boxes, set-up and pixel passes of :func:`mesh2tex.render.rasterize` as one compiled CPU loop
(numba).

On the CPU, the vectorised passes (:mod:`mesh2tex.render.binning`, the set-up in
:mod:`mesh2tex.render.rasterize`) spend most of their time writing and reading temporaries the size
of every (view, triangle) pair and building index tensors, and with several torch threads they
stall when the machine is busy. This loop visits each (view, triangle) pair once, on one thread,
with no temporaries, and in each row of a triangle's box only the columns that its edges do not
rule out (:func:`_row_span`): its cost follows the triangles and the pixels they cover.

It evaluates exactly the expressions of the vectorised path, in the same order and precision
(float32 boxes and pixel tests, float64 set-up, a fused multiply-add wherever torch's ``addcmul``
computes one), so every pixel is classified the same way: covered when its three scaled edge values
are above 1, outside when one is below -1, set aside for the exact test
(:class:`~mesh2tex.render.edges.EdgeTest`) otherwise; depth keys are the same integers. The
rasterizer's output is identical bit for bit on both paths (``tests/test_rasterize_kernel.py``).
On a CPU without fused multiply-add instructions torch's ``addcmul`` rounds twice; coverage stays
exact there, but depth keys may then differ in the last bit from the vectorised path's.

The exact test of the band pixels and the barycentrics of each pixel's winner stay in torch (they
concern few pixels, and the covered ones). A call with a triangle crossing the near plane (rare: the
camera inside a mesh) takes the vectorised path. numba compiles the loop on first use (about 6 s,
cached on disk after that; ``make install`` does it, :func:`warm_up`). Where numba is not installed,
or ``MESH2TEX_RASTER_KERNEL=torch`` is set, the vectorised path runs.
"""

from __future__ import annotations

import math
import os
import sys
import threading

import numpy as np
import torch

try:  # numba is a dependency; the vectorised passes remain the fallback and the CUDA path.
    import numba
    import numba.extending
except ImportError:  # pragma: no cover - exercised only where numba is missing
    numba = None

# The vectorised path's constants, in the precision the loop uses them in. They are written out here,
# not imported: numba compiles module globals into the cached machine code and re-checks only this
# file for changes, so an imported value changed elsewhere would leave a stale cache.
# tests/test_rasterize_kernel.py checks each against its namesake.
_BOX_MARGIN = np.float32(1e-3)  # rasterize._BOX_MARGIN
_WHOLE = 16  # binning.WHOLE
_REGION = 64  # binning.REGION
_BAND = np.float32(2.0**-18)  # edges._BAND
_SETUP_ROUNDING = 2.0**-40  # edges._SETUP_ROUNDING
_SCALE_FLOOR = np.float32(2.0**-100)  # edges._SCALE_FLOOR
# Band pixels a call expects at first; a call with more runs once more with room for all.
BAND_CAPACITY = 4096


# Compiled lazily, on first call; plain Python (unused) where numba is missing.
# error_model "numpy": a division by zero gives inf or NaN, as in torch, instead of raising.
_jit = numba.njit(cache=True, nogil=True, error_model="numpy") if numba is not None else (lambda function: function)
# The box's small steps, inlined where they are used (the vertex pass runs them for every vertex of every view).
_jit_inline = (
    numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
    if numba is not None
    else (lambda function: function)
)

if numba is not None:

    @numba.extending.intrinsic
    def _fma(typingctx, a, b, c):
        """a * b + c rounded once, as torch.addcmul computes it on the CPU."""
        return a(a, b, c), lambda context, builder, signature, args: builder.fma(*args)
else:  # pragma: no cover

    def _fma(a, b, c):
        return a * b + c


def available() -> bool:
    """Whether the compiled loop can run (numba importable and not switched off)."""
    return numba is not None and os.environ.get("MESH2TEX_RASTER_KERNEL", "numba") != "torch"


@_jit_inline
def _first_centre(coordinate, size):
    """The first pixel centre at or after a float32 pixel coordinate (less the box margin), clamped to
    [0, size]. Rounded and clamped in float32, where the clamps' small integers are exact, then
    converted: a corner far outside the image (NDC 1e20) is beyond int64's range until it is clamped,
    and numba's math.ceil on a float32 converts to int64 at 3x the cost of the rest."""
    return np.int64(min(max(np.ceil(coordinate - _BOX_MARGIN), np.float32(0.0)), np.float32(size)))


@_jit_inline
def _last_centre(coordinate, size):
    """The last pixel centre at or before a float32 pixel coordinate (plus the box margin), clamped to
    [-1, size - 1], as :func:`_first_centre`."""
    return np.int64(min(max(np.floor(coordinate + _BOX_MARGIN), np.float32(-1.0)), np.float32(size - 1)))


@_jit_inline
def _pixel_col(x, W):
    """Float32 pixel column of NDC x (pixel centres at the integers)."""
    return ((x + np.float32(1.0)) * np.float32(W) - np.float32(1.0)) * np.float32(0.5)


@_jit_inline
def _pixel_row(y, H):
    """Float32 pixel row of NDC y (pixel centres at the integers, row 0 at the top)."""
    return ((np.float32(1.0) - y) * np.float32(H) - np.float32(1.0)) * np.float32(0.5)


@_jit
def _box(x0, x1, x2, y0, y1, y2, H, W):
    """Pixel box (row0, col0, rows, cols) of one triangle in front of the near plane from the float32
    NDC x, y of its corners, as ``rasterize._pixel_boxes``; rows * cols = 0 when it draws nothing."""
    x_min, x_max = _min3(x0, x1, x2), _max3(x0, x1, x2)
    y_min, y_max = _min3(y0, y1, y2), _max3(y0, y1, y2)
    if not math.isfinite(((x_min + x_max) + y_min) + y_max):
        return 0, 0, 0, 0
    col_lo, col_hi = _first_centre(_pixel_col(x_min, W), W), _last_centre(_pixel_col(x_max, W), W)
    row_lo, row_hi = _first_centre(_pixel_row(y_max, H), H), _last_centre(_pixel_row(y_min, H), H)
    return row_lo, col_lo, max(row_hi - row_lo + 1, 0), max(col_hi - col_lo + 1, 0)


# NDC magnitude below which a vertex's box bounds are kept as integers (far inside int32 after clamping;
# a sum of four such values cannot overflow float32, so :func:`_box`'s finiteness test passes).
_PLAIN_NDC = np.float32(1e15)


@_jit
def _vertex_bounds(x, y, H, W, bounds, v):
    """One vertex's share of :func:`_box`, from its float32 NDC x, y: bounds[v] (4,) int32 = (first row,
    last row, first column, last column) it allows, each clamped as the box clamps it; bounds[v, 0] =
    -2 when the vertex is not plain (NaN, infinite or beyond :data:`_PLAIN_NDC`), for :func:`_box`.

    Exact: every float32 operation of the box's bounds (add, multiply, ceil, floor, the clamps) is
    monotone, so the bound of the triangle's extreme vertex is the extreme of its vertices' bounds:
    a triangle's box is (min bounds[:, 0], max [:, 1], min [:, 2], max [:, 3]) over its corners."""
    if not (abs(x) < _PLAIN_NDC and abs(y) < _PLAIN_NDC):
        bounds[v, 0] = -2
        return
    col, row = _pixel_col(x, W), _pixel_row(y, H)
    bounds[v, 0], bounds[v, 1] = _first_centre(row, H), _last_centre(row, H)
    bounds[v, 2], bounds[v, 3] = _first_centre(col, W), _last_centre(col, W)


@_jit
def _view_vertices(pos, view, H, W, ndc_x, ndc_y, ahead, bounds):
    """Per vertex of one view of pos (B,V,4): float32 NDC x, y, whether it is in front of the near
    plane and its :func:`_vertex_bounds`, into the (V,) and (V,4) arrays; returns whether all are in
    front (the usual view: none of its triangles needs the near-plane test)."""
    all_ahead = True
    for v in range(pos.shape[1]):
        x32, y32 = np.float32(pos[view, v, 0]), np.float32(pos[view, v, 1])
        z32, w32 = np.float32(pos[view, v, 2]), np.float32(pos[view, v, 3])
        ndc_x[v], ndc_y[v], ahead[v] = x32 / w32, y32 / w32, z32 + w32 >= 0
        _vertex_bounds(ndc_x[v], ndc_y[v], H, W, bounds, v)
        all_ahead = all_ahead and ahead[v]
    return all_ahead


@_jit
def _triangle_box(i0, i1, i2, bounds, ndc_x, ndc_y, H, W):
    """The pixel box (row0, col0, rows, cols) of the triangle of vertices i0, i1, i2, as :func:`_box`.
    Most pairs of a fine mesh cover no pixel centre: they are rejected from the vertices' integer
    bounds; a vertex that is not plain sends the triangle to the float box and its finiteness test."""
    row0 = min(bounds[i0, 0], bounds[i1, 0], bounds[i2, 0])
    if row0 < 0:
        return _box(ndc_x[i0], ndc_x[i1], ndc_x[i2], ndc_y[i0], ndc_y[i1], ndc_y[i2], H, W)
    col0 = min(bounds[i0, 2], bounds[i1, 2], bounds[i2, 2])
    rows = max(max(bounds[i0, 1], bounds[i1, 1], bounds[i2, 1]) - row0 + 1, 0)
    cols = max(max(bounds[i0, 3], bounds[i1, 3], bounds[i2, 3]) - col0 + 1, 0)
    return np.int64(row0), np.int64(col0), np.int64(rows), np.int64(cols)


@_jit
def _min3(a, b, c):  # NaN-propagating, as torch.minimum
    if a != a or b != b or c != c:
        return np.float32(np.nan)
    return min(min(a, b), c)


@_jit
def _max3(a, b, c):
    if a != a or b != b or c != c:
        return np.float32(np.nan)
    return max(max(a, b), c)


@_jit
def _setup(x, y, z, w, row0, col0, H, W, p):
    """Fill p (3,4) float64 with the planes of ``rasterize._edge_setup`` relative to (row0, col0);
    returns the determinant."""
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        p[1, i] = y[j] * w[k] - w[j] * y[k]
        p[2, i] = w[j] * x[k] - x[j] * w[k]
        p[0, i] = x[j] * y[k] - y[j] * x[k]
    det = (x[0] * p[1, 0] + y[0] * p[2, 0]) + w[0] * p[0, 0]
    for r in range(3):
        for i in range(3):
            p[r, i] /= det
        p[r, 3] = (p[r, 0] * z[0] + p[r, 1] * z[1]) + p[r, 2] * z[2]
    ref_x = (2 * col0 + 1) / W - 1.0
    ref_y = 1.0 - (2 * row0 + 1) / H
    for c in range(4):
        p[0, c] = _fma(p[2, c], ref_y, _fma(p[1, c], ref_x, p[0, c]))
        p[1, c] *= 2.0 / W
        p[2, c] *= -2.0 / H
    return det


@_jit
def _band_scale(p, size, det, rows, cols, scale):
    """Fill scale (3,) float32 as ``edges.band_scale``."""
    roundoff = np.float32(size * size * _SETUP_ROUNDING / abs(det))
    reach_c, reach_r = np.float32(cols + 64), np.float32(rows + 64)
    for i in range(3):
        tau = _fma(abs(np.float32(p[2, i])), reach_r, _fma(abs(np.float32(p[1, i])), reach_c, abs(np.float32(p[0, i]))))
        tau = _fma(tau, _BAND, roundoff)
        scale[i] = np.float32(1.0) / tau if tau > _SCALE_FLOOR else np.float32(0.0)


@_jit
def _row_span(at, step, first, last):
    """Narrow the columns [first, last] of a row to those where the edge value ``fma(step, c, at)``
    (float32) may be at least -1. Conservative: the bound is computed in float64 with a margin of
    1e-6 in value (the float32 rounding of a value near -1 is 6e-8) and one column, so no pixel the
    test would keep is skipped. NaN or infinite planes leave the row whole."""
    if not (math.isfinite(at) and math.isfinite(step)) or step == 0:
        return first, last
    bound = (-1.000001 - np.float64(at)) / np.float64(step)  # where the exact value crosses -1 - 1e-6
    if step > 0:  # values rise with the column: below the bound they are under -1
        if bound > last + 1:
            return 1, 0
        if bound > first:
            first = max(first, int(math.floor(bound)) - 1)
    else:
        if bound < first - 1:
            return 1, 0
        if bound < last:
            last = min(last, int(math.ceil(bound)) + 1)
    return first, last


@_jit
def _draw(q, rows, cols, base, face, setup, keys, row_stride, id_bits, depth_scale, band, n_band):
    """Depth-test the pixels of one rectangle with float32 planes q (12,) (rows as in
    :class:`~mesh2tex.render.binning.Entries`); band pixels go to ``band`` (3, capacity) as far as
    it holds them. Returns the new band count."""
    one = np.float32(1.0)
    for dr in range(rows):
        fr = np.float32(dr)
        a0, a1, a2, az = _fma(q[8], fr, q[0]), _fma(q[9], fr, q[1]), _fma(q[10], fr, q[2]), _fma(q[11], fr, q[3])
        row_base = base + dr * row_stride
        first, last = 0, cols - 1
        if cols > 8:  # long rows: skip the columns where an edge is surely below -1
            first, last = _row_span(a0, q[4], first, last)
            first, last = _row_span(a1, q[5], first, last)
            first, last = _row_span(a2, q[6], first, last)
        for dc in range(first, last + 1):
            fc = np.float32(dc)
            l0, l1, l2 = _fma(q[4], fc, a0), _fma(q[5], fc, a1), _fma(q[6], fc, a2)
            # NaN fails every comparison, as it fails the vectorised ``min >= -1``.
            if not (l0 >= -one and l1 >= -one and l2 >= -one):
                continue
            z = _fma(q[7], fc, az)
            if not (abs(z) <= one):  # near and far planes
                continue
            key = (np.int64((np.float64(z) + 1.0) * depth_scale) << id_bits) | face
            pixel = row_base + dc
            if l0 <= one or l1 <= one or l2 <= one:
                if n_band < band.shape[1]:
                    band[0, n_band], band[1, n_band], band[2, n_band] = pixel, key, setup
                n_band += 1
            elif key < keys[pixel]:
                keys[pixel] = key
    return n_band


@_jit
def _rasterize_views(
    pos, tri, H, W, cull, keys, view_stride, row_stride, id_bits, depth_scale, live, box, params, front, band
):
    """Boxes, set-up and pixel passes of every (view, triangle) pair: pos (B,V,4), tri (T,3).

    Writes the live set-ups (those that draw) to ``live`` (L,) (view * T + triangle), ``box`` (L,2)
    origin, ``params`` (L,12) float64 and ``front`` (L,); band
    pixels to ``band`` (3, capacity). Returns (L, band count), or (-1, 0) at the first triangle
    crossing the near plane."""
    B, V, T = pos.shape[0], pos.shape[1], tri.shape[0]
    x, y, z, w = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    p = np.empty((3, 4))
    scale = np.empty(3, dtype=np.float32)
    q = np.empty(12, dtype=np.float32)
    # Per vertex of a view, once: float32 NDC x and y, and whether it is in front of the near plane.
    ndc_x, ndc_y = np.empty(V, dtype=np.float32), np.empty(V, dtype=np.float32)
    ahead = np.empty(V, dtype=np.bool_)
    bounds = np.empty((V, 4), dtype=np.int32)  # _vertex_bounds of each vertex
    n_live, n_band = 0, 0
    for view in range(B):
        all_ahead = _view_vertices(pos, view, H, W, ndc_x, ndc_y, ahead, bounds)
        for face in range(T):
            i0, i1, i2 = tri[face, 0], tri[face, 1], tri[face, 2]
            if not all_ahead:
                n_ahead = np.int64(ahead[i0]) + np.int64(ahead[i1]) + np.int64(ahead[i2])
                if n_ahead < 3:
                    if n_ahead > 0:
                        return -1, 0
                    continue
            row0, col0, rows, cols = _triangle_box(i0, i1, i2, bounds, ndc_x, ndc_y, H, W)
            if rows * cols == 0:
                continue
            size = 0.0
            for k in range(3):
                vertex = tri[face, k]
                x[k], y[k], z[k], w[k] = (
                    pos[view, vertex, 0],
                    pos[view, vertex, 1],
                    pos[view, vertex, 2],
                    pos[view, vertex, 3],
                )
                size = max(size, abs(x[k]), abs(y[k]), abs(z[k]), abs(w[k]))
            det = _setup(x, y, z, w, row0, col0, H, W, p)
            if not math.isfinite(1.0 / det) or (cull and not det > 0):
                continue
            _band_scale(p, size, det, rows, cols, scale)
            base = view * view_stride + row0 * row_stride + col0
            live[n_live], box[n_live, 0], box[n_live, 1], front[n_live] = view * T + face, row0, col0, det > 0
            for r in range(3):  # one set-up's planes side by side: a row of (L, 12)
                for c in range(4):
                    params[n_live, r * 4 + c] = p[r, c]
            if rows <= _WHOLE and cols <= _WHOLE:
                _scaled(p, scale, False, 0, 0, q)
                n_band = _draw(q, rows, cols, base, face, n_live, keys, row_stride, id_bits, depth_scale, band, n_band)
            else:  # regions of at most _REGION pixels a side, their planes rebased in float64
                for off_r in range(0, rows, _REGION):
                    for off_c in range(0, cols, _REGION):
                        _scaled(p, scale, True, off_r, off_c, q)
                        n_band = _draw(
                            q,
                            min(rows - off_r, _REGION),
                            min(cols - off_c, _REGION),
                            base + off_r * row_stride + off_c,
                            face,
                            n_live,
                            keys,
                            row_stride,
                            id_bits,
                            depth_scale,
                            band,
                            n_band,
                        )
            n_live += 1
    return n_live, n_band


@_jit
def _scaled(p, scale, rebase, off_r, off_c, q):
    """q (12,) float32: the planes p (3,4), rebased by (off_r, off_c) pixels if ``rebase`` (a region,
    as ``rasterize._regions``), edge planes times their band scale (``rasterize._scaled``)."""
    for c in range(4):
        value = p[0, c]
        if rebase:
            value = value + (p[1, c] * off_c + p[2, c] * off_r)
        q[c], q[4 + c], q[8 + c] = np.float32(value), np.float32(p[1, c]), np.float32(p[2, c])
    for i in range(3):
        q[i] *= scale[i]
        q[4 + i] *= scale[i]
        q[8 + i] *= scale[i]


# Per thread, the arrays the loop wrote its set-ups into on that thread's last call (see _setups_scratch).
_SCRATCH = threading.local()
# Pairs beyond which a call's arrays are not kept for the next (121 bytes a pair: 2**20 pairs, 127 MB).
_SCRATCH_PAIRS = 2**20


def _setups_scratch(pairs: int):
    """Arrays for the set-ups of up to ``pairs`` (view, triangle) pairs: live (N,) int64, box (N,2)
    int64, params (N,12) float64 (row-major: a set-up's planes are written together, strided writes
    to twelve (12, N) rows cost a third of the loop), front (N,) bool.

    The last call's arrays are handed out again when they are large enough and nothing holds a view
    of them (the rasterizer drops its views before it returns): fresh pages cost a page fault each,
    about 2 ms of a 25 ms 8-view call on a 100k-triangle mesh. Calls beyond _SCRATCH_PAIRS pairs get
    their own arrays, so a large render leaves no large arrays behind."""
    held = getattr(_SCRATCH, "arrays", None)
    # A view of an array holds a reference to it: reuse only at the count measured when nothing did.
    if held is not None and held[0].shape[0] >= pairs and _references(held) == _SCRATCH.unheld:
        return held
    arrays = (
        np.empty(pairs, dtype=np.int64),
        np.empty((pairs, 2), dtype=np.int64),
        np.empty((pairs, 12)),
        np.empty(pairs, dtype=np.bool_),
    )
    _SCRATCH.arrays = arrays if pairs <= _SCRATCH_PAIRS else None
    _SCRATCH.unheld = _references(arrays)  # measured the same way as the check, whatever the interpreter counts
    return arrays


def _references(arrays) -> list[int]:
    """Each array's reference count, as :func:`_setups_scratch` compares them."""
    return [sys.getrefcount(array) for array in arrays]


def rasterize_views(pos: torch.Tensor, tri: torch.Tensor, resolution, cull_backfaces: bool, buffer):
    """Draw every (view, triangle) pair into ``buffer`` (a CPU
    :class:`~mesh2tex.render.binning.DepthBuffer`); its band pixels go to ``buffer.undecided``.

    Args:
        pos: (B,V,4) float32 or float64 clip-space vertices; tri: (T,3) int64.
    Returns:
        None when a triangle crosses the near plane (nothing drawn: use the vectorised path), else
        live (L,) int64 (view * T + triangle) of each set-up, row0, col0 (L,) int64 its box origin,
        params64 (12,L) float64 its planes relative to it (a view of a row-major (L,12) array, set-up
        last by ``movedim``: :func:`~mesh2tex.render.binning.columns` gathers its rows), front (L,) bool.
    """
    H, W = int(resolution[0]), int(resolution[1])
    positions = pos.detach().contiguous().numpy()
    faces = tri.contiguous().numpy()
    # The loop reads vertices without bounds checks: a bad index must stop here.
    if faces.size and (faces.min() < 0 or faces.max() >= positions.shape[1]):
        raise ValueError(
            f"rasterize: tri holds vertex indices {faces.min()}..{faces.max()}, pos has {positions.shape[1]} vertices"
        )
    live, box, params, front = _setups_scratch(positions.shape[0] * faces.shape[0])
    capacity = BAND_CAPACITY
    keys = buffer.keys.numpy()  # shares memory: updated in place
    view_stride = buffer.shape[1] * buffer.row_stride
    while True:
        band = np.empty((3, capacity), dtype=np.int64)
        # Re-running after an overflow is harmless: depth-testing the same keys again changes nothing.
        n_live, n_band = _rasterize_views(
            positions,
            faces,
            H,
            W,
            cull_backfaces,
            keys,
            view_stride,
            buffer.row_stride,
            buffer.id_bits,
            buffer.depth_scale,
            live,
            box,
            params,
            front,
            band,
        )
        if n_live < 0:
            return None
        if n_band <= capacity:
            break
        capacity = n_band
    if n_band:
        buffer.undecided.append(tuple(torch.from_numpy(band[i, :n_band].copy()) for i in range(3)))
    box = torch.from_numpy(box[:n_live])
    return (
        torch.from_numpy(live[:n_live]),
        box[:, 0],
        box[:, 1],
        torch.from_numpy(params[:n_live]).movedim(0, -1),
        torch.from_numpy(front[:n_live]),
    )


def warm_up() -> None:
    """Compile the loop for float32 positions now (or load it from numba's cache), so that the first
    render does not wait for it; ``make install`` calls this."""
    if not available():
        return
    from mesh2tex.render.binning import WHOLE, DepthBuffer

    corners = torch.tensor([[[-0.5, -0.5, 0.5, 1.0], [0.5, -0.5, 0.5, 1.0], [0.0, 0.5, 0.5, 1.0]]])
    rasterize_views(corners, torch.tensor([[0, 1, 2]]), (4, 4), False, DepthBuffer(1, (4, 4), (WHOLE, WHOLE), 1, "cpu"))
