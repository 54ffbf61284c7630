"""A triangle rasterizer: vectorised PyTorch passes (CUDA, and the CPU fallback) and, on the CPU, the
same computation as one compiled loop (:mod:`mesh2tex.render.kernels`, numba) that gives the same
result bit for bit. No C++ or CUDA extension to build.

Method (homogeneous rasterization, no geometric clipping):
  1. Per triangle, the 2D-homogeneous edge functions ``lambda_i(p) = e_i . (x, y, 1) / det`` with
     ``e_i = v_j x v_k`` over the clip-space columns ``v = (x, y, w)``. For a pixel centre p they equal
     the perspective-correct barycentrics divided by the clip w of the surface point, so
     ``bary = lambda / sum(lambda)``, ``1 / w = sum(lambda)`` and NDC ``z = sum(lambda_i z_i)`` is affine
     in screen space. A pixel is covered when every ``lambda_i >= 0`` (which also puts the surface point
     in front of the camera, w > 0) and ``-1 <= z <= 1`` (near and far planes, tested per pixel). This
     is exact for triangles that cross the near plane or reach behind the camera: no garbage, no
     clipping into new triangles. The set-up runs in float64; the per-pixel tests in float32 relative to
     a reference pixel, so nothing cancels catastrophically. Coverage is watertight: the float32 edge
     values are scaled so that outside [-1, 1] their sign is certain (``edges.band_scale``); the few
     pixels within that band of an edge (a small fraction of a pixel from it, or on it) are decided
     from the vertices in exact arithmetic (``edges.EdgeTest``), where the two triangles of a shared
     edge take opposite sides, and a centre exactly on an edge goes to the triangle that holds it
     shifted right, then down, by an infinitesimal (the top-left rule): drawn exactly once.
  2. Per triangle and view, a pixel bounding box (of the triangle clipped to the near plane) gives the
     candidate pixels; boxes holding no pixel centre (sub-pixel triangles between centres, off
     screen) are dropped before the set-up. Boxes of at most 16x16 pixels (most boxes of most
     meshes) are sorted into bins by size rounded up to powers of two, and each bin is evaluated as
     a dense (n, rows, cols) grid of edge functions. Larger boxes (cut into 64-pixel regions) go
     through a coarse pass by pixel rows: per row, each edge bounds the columns it allows, so only
     the row's span is visited, and its pixels well inside all three bounds are taken without tests
     (``binning.row_spans``). A large triangle thus costs its covered pixels plus a few per row,
     whatever the shape of its box. Everything runs in chunks of at most ``max_pairs`` candidates,
     so memory stays bounded. The visibility buffer is padded by the largest stencil, so stencil
     pixels past the image edge need no test; depth is computed at hits only.
  3. Visibility: one ``scatter_reduce('amin')`` per chunk over an int64 key per covered pair, the
     quantised depth in the high bits and the triangle's index in the low bits. Ties go to the lower
     triangle index, so results are deterministic. The band's pixels are set aside and depth-tested
     together once the exact test has decided them (``DepthBuffer.settle``).
  4. Only the winning triangle of each pixel gets its barycentrics and depth computed (float64, cast to
     float32), so they are not quantised.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass

import torch

from mesh2tex.checks import check_shape
from mesh2tex.render import kernels
from mesh2tex.render.binning import (
    N_BINS,
    REGION,
    WHOLE,
    DepthBuffer,
    Entries,
    bin_slices,
    columns,
    draw,
    draw_spans,
    size_bins,
    split,
)
from mesh2tex.render.edges import EdgeTest, band_scale

# Candidate (triangle, pixel) pairs handled at once; about 130 bytes of temporaries each.
DEFAULT_MAX_PAIRS = 1 << 21
# Bounding boxes grow by this fraction of a pixel so that pixel centres exactly on an edge are tested.
_BOX_MARGIN = 1e-3


@dataclass
class Raster:
    """Result of :func:`rasterize`.

    Attributes:
        face_id: (B,H,W) int64, index into ``tri`` of the visible triangle, -1 for background.
        bary: (B,H,W,3) float32, perspective-correct barycentrics of the triangle's three vertices in
            the order of ``tri``; 0 on background. Not differentiable (gradients reach attributes
            through :func:`mesh2tex.render.interpolate`).
        depth: (B,H,W) float32, NDC z in [-1, 1] of the visible surface (smaller is nearer); 1 on
            background.
    """

    face_id: torch.Tensor
    bary: torch.Tensor
    depth: torch.Tensor

    @property
    def mask(self) -> torch.Tensor:
        """(B,H,W) bool, True where a triangle is visible."""
        return self.face_id >= 0

    @property
    def resolution(self) -> tuple[int, int]:
        return tuple(self.face_id.shape[1:3])


def pixel_centres(resolution, device=None, dtype=torch.float32) -> torch.Tensor:
    """NDC coordinates of the pixel centres: (H,W,2), x = (2j+1)/W - 1, y = 1 - (2i+1)/H."""
    H, W = resolution
    x = (2 * torch.arange(W, device=device, dtype=torch.float64) + 1) / W - 1
    y = 1 - (2 * torch.arange(H, device=device, dtype=torch.float64) + 1) / H
    return torch.stack(torch.meshgrid(x, y, indexing="xy"), dim=-1).to(dtype)


def _pixel_boxes(corners: torch.Tensor, resolution):
    """Candidate pixel box of every (view, triangle): the box of its part in front of the near plane.

    Args:
        corners: (4,B,3,T) float32 clip-space vertices: component (x, y, z, w), view, corner, triangle.
    Returns:
        row0, col0, rows, cols: (B,T) int64 box origin and size in pixels; 0 rows where nothing can be
        drawn (behind the near plane, off screen, or between pixel centres).
    """
    H, W = resolution
    x, y, z, w = corners  # each (B,3,T)
    in_front = z + w >= 0  # OpenGL near plane: z_ndc >= -1
    all_front = in_front.all(1)
    ndc_x, ndc_y = x / w, y / w
    x_min = torch.minimum(torch.minimum(ndc_x[:, 0], ndc_x[:, 1]), ndc_x[:, 2])
    x_max = torch.maximum(torch.maximum(ndc_x[:, 0], ndc_x[:, 1]), ndc_x[:, 2])
    y_min = torch.minimum(torch.minimum(ndc_y[:, 0], ndc_y[:, 1]), ndc_y[:, 2])
    y_max = torch.maximum(torch.maximum(ndc_y[:, 0], ndc_y[:, 1]), ndc_y[:, 2])
    usable = all_front.clone()

    # Triangles crossing the near plane (rare): box of the kept vertices and the edge crossings.
    crossing_tri = torch.nonzero((~all_front & in_front.any(1)).reshape(-1)).squeeze(1)
    if crossing_tri.numel():
        T = corners.shape[-1]
        view, face = crossing_tri // T, crossing_tri % T
        c = corners[:, view, :, face].permute(0, 2, 1).double()  # (N,3,4)
        dist = c[..., 2] + c[..., 3]  # (N,3) scaled signed distance to the near plane
        nxt = [1, 2, 0]
        d0, d1 = dist, dist[:, nxt]
        crosses = (d0 * d1) < 0
        t = (d0 / torch.where(crosses, d0 - d1, torch.ones_like(d0))).clamp(0, 1)
        cut = c + t[..., None] * (c[:, nxt] - c)
        points = torch.cat([c, cut], dim=1)  # (N,6,4)
        valid = torch.cat([dist >= 0, crosses], dim=1) & (points[..., 3] > 0)
        safe_w = torch.where(valid, points[..., 3], torch.ones_like(points[..., 3]))
        px, py = points[..., 0] / safe_w, points[..., 1] / safe_w
        inf = torch.full_like(px, float("inf"))
        for bound, value in (
            (x_min, torch.where(valid, px, inf).amin(1)),
            (x_max, torch.where(valid, px, -inf).amax(1)),
            (y_min, torch.where(valid, py, inf).amin(1)),
            (y_max, torch.where(valid, py, -inf).amax(1)),
        ):
            bound.view(-1)[crossing_tri] = value.float()
        usable.view(-1)[crossing_tri] = valid.any(1)

    # NDC -> continuous pixel coordinates whose integers are pixel centres; the integer range inside.
    col_lo = torch.ceil(((x_min + 1) * W - 1) * 0.5 - _BOX_MARGIN).clamp(0, W)
    col_hi = torch.floor(((x_max + 1) * W - 1) * 0.5 + _BOX_MARGIN).clamp(-1, W - 1)
    row_lo = torch.ceil(((1 - y_max) * H - 1) * 0.5 - _BOX_MARGIN).clamp(0, H)
    row_hi = torch.floor(((1 - y_min) * H - 1) * 0.5 + _BOX_MARGIN).clamp(-1, H - 1)
    usable &= torch.isfinite(x_min + x_max + y_min + y_max)
    col0 = col_lo.nan_to_num(0).long()
    row0 = row_lo.nan_to_num(0).long()
    cols = (col_hi.nan_to_num(-1).long() - col0 + 1).clamp(min=0)
    rows = (row_hi.nan_to_num(-1).long() - row0 + 1).clamp(min=0) * usable
    return row0, col0, rows, cols


def _edge_setup(clip: torch.Tensor, resolution, row0, col0):
    """Edge-function and depth-plane coefficients of N triangles, relative to their box origin.

    Args:
        clip: (4,3,N) float64 clip-space vertices: component (x, y, z, w), corner, triangle.
        row0, col0: (N,) int64 box origin (the reference pixel).
    Returns:
        params: (12,N) float64, rows 0-3: lambda_0, lambda_1, lambda_2 and NDC z at the reference
            pixel; rows 4-7: their change per pixel step right; rows 8-11: per pixel step down. Rows
            (not columns) keep the per-pixel arithmetic on contiguous memory.
        det: (N,) float64 determinant of the (x, y, w) vertex columns; > 0 for counter-clockwise faces.
    """
    H, W = resolution
    x, y, z, w = clip  # (3,N): one row per corner
    # params[c, i]: lambda_i = params[1, i] * x_ndc + params[2, i] * y_ndc + params[0, i]; column 3 is
    # z_ndc. Unnormalised, lambda_i's coefficients are e_i = v_j x v_k over (x, y, w): the adjugate of
    # [v0 v1 v2]. Written in place, row by row: large temporaries cost page faults on the CPU.
    params = torch.empty(3, 4, clip.shape[2], dtype=clip.dtype, device=clip.device)
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        for row, (a, b) in ((1, (y, w)), (2, (w, x)), (0, (x, y))):
            torch.mul(a[j], b[k], out=params[row, i])
            params[row, i].sub_(b[j] * a[k])
    det = x[0] * params[1, 0] + y[0] * params[2, 0] + w[0] * params[0, 0]
    params[:, :3] /= det
    torch.mul(params[:, 0], z[0], out=params[:, 3])
    params[:, 3] += params[:, 1] * z[1]
    params[:, 3] += params[:, 2] * z[2]
    # Rebase to the reference pixel; per-pixel steps right and down.
    ref_x = (2 * col0 + 1).to(clip.dtype) / W - 1
    ref_y = 1 - (2 * row0 + 1).to(clip.dtype) / H
    params[0].addcmul_(params[1], ref_x).addcmul_(params[2], ref_y)
    params[1] *= 2.0 / W
    params[2] *= -2.0 / H
    return params.view(12, -1), det


def _regions(params64, scale, rows, cols):
    """Cut pixel boxes into regions of at most REGION x REGION pixels with their own planes.

    Args:
        params64: (12,N) float64 from :func:`_edge_setup`, relative to each box origin.
        scale: (3,N) float32 band scale of the edge planes (:func:`~mesh2tex.render.edges.band_scale`).
        rows, cols: (N,) int64 box sizes.
    Returns:
        owner (E,) index into N; off_r, off_c, rows, cols (E,) of each region relative to its box;
        params (12,E) float32 rebased (in float64) to the region's origin, edge planes scaled.
    """
    owner, off_r, off_c, rows, cols = split(rows, cols, REGION)
    p = columns(params64, owner)
    p[0:4] += p[4:8] * off_c.double() + p[8:12] * off_r.double()
    return owner, off_r, off_c, rows, cols, _scaled(p, columns(scale, owner))


def _scaled(params64, scale):
    """(12,N) float64 planes -> float32 with the edge planes (not depth) multiplied by their band
    scale (3,N), so that the band of uncertain values is [-1, 1] for every edge."""
    p = params64.float()
    p.view(3, 4, -1)[:, :3] *= scale
    return p


def gather_corners(pos: torch.Tensor, tri: torch.Tensor) -> torch.Tensor:
    """(B,V,4) clip-space positions and (T,3) int64 indices -> (4,3,B*T) corners, component-major,
    so that every per-(view, triangle) quantity is a contiguous row."""
    B, T = pos.shape[0], tri.shape[0]
    # Gather whole (x, y, z, w) rows first, then transpose: no (4, 3, B, T) index tensor to build
    # (77 MB for 8 views of 100k triangles), and the same values, bit for bit.
    rows = pos.detach().index_select(1, tri.T.reshape(-1))  # (B, 3*T, 4), corner-major
    return rows.view(B, 3, T, 4).permute(3, 1, 0, 2).reshape(4, 3, B * T)


@dataclass
class Setups:
    """The live (view, triangle) pairs of a call, those whose box holds a pixel centre and that are
    not degenerate (or culled), sorted by size bin: each bin a contiguous slice, the large boxes last.

    Attributes:
        live: (L,) int64 index into the (view, triangle) pairs (view * T + triangle).
        row0, col0, rows, cols: (L,) int64 pixel boxes.
        params64: (12,L) float64 planes relative to each box origin (see :func:`_edge_setup`).
        scale: (3,L) float32 band scale of each edge plane (:func:`~mesh2tex.render.edges.band_scale`).
        front: (L,) bool, counter-clockwise in NDC (positive determinant).
        counts: N_BINS + 1 ints, the live boxes in each size bin (:func:`size_bins`), then the boxes
            over WHOLE pixels a side.
    """

    live: torch.Tensor
    row0: torch.Tensor
    col0: torch.Tensor
    rows: torch.Tensor
    cols: torch.Tensor
    params64: torch.Tensor
    scale: torch.Tensor
    front: torch.Tensor
    counts: list[int]


def _live_setup(corners: torch.Tensor, resolution, cull_backfaces: bool) -> Setups:
    """Boxes of every (view, triangle), then the float64 set-up of those that can draw a pixel.

    Args:
        corners: (4,3,N) clip-space vertices (pos's dtype): component, corner, (view, triangle).
    """
    row0, col0, rows, cols = (t.view(-1) for t in _pixel_boxes(corners.float()[:, None], resolution))
    # Boxes holding no pixel centre (sub-pixel triangles between centres, off screen, behind the
    # near plane) sort last and are dropped before the set-up, so they cost only their box.
    small = (rows <= WHOLE) & (cols <= WHOLE)
    bins = torch.where(small, size_bins(rows.clamp(1, WHOLE), cols.clamp(1, WHOLE)), N_BINS)
    bins = torch.where(rows * cols > 0, bins, N_BINS + 1)
    live = torch.argsort(bins, stable=True)
    counts = torch.bincount(bins, minlength=N_BINS + 2).tolist()[: N_BINS + 1]
    live = live[: sum(counts)]
    row0, col0, rows, cols = (t.index_select(0, live) for t in (row0, col0, rows, cols))
    clip = columns(corners, live)
    size = clip.abs().amax((0, 1))
    params64, det = _edge_setup(clip.double(), resolution, row0, col0)
    # Degenerate triangles (seen edge-on, or through the eye) and culled ones draw nothing.
    keep = torch.isfinite(1.0 / det)
    if cull_backfaces:
        keep &= det > 0
    if not bool(keep.all()):
        keep = torch.nonzero(keep).squeeze(1)
        counts = torch.bincount(bins.index_select(0, live.index_select(0, keep)), minlength=N_BINS + 1).tolist()
        live, row0, col0, rows, cols, det, size = (
            t.index_select(0, keep) for t in (live, row0, col0, rows, cols, det, size)
        )
        params64 = columns(params64, keep)
    scale = band_scale(params64, size, det, rows, cols)
    return Setups(live, row0, col0, rows, cols, params64, scale, det > 0, counts)


def _draw_large(buffer: DepthBuffer, setups: Setups, first: int, base, face, max_pairs: int):
    """The coarse pass, then the fine pass, for the boxes larger than WHOLE x WHOLE pixels: the
    set-ups from index ``first`` on.

    Args:
        base: (N,) int64 flat index into ``buffer`` of each box origin (of the set-ups from ``first``).
        face: (N,) int64 triangle index.
    """
    owner, off_r, off_c, r_rows, r_cols, r_params = _regions(
        setups.params64[:, first:], setups.scale[:, first:], setups.rows[first:], setups.cols[first:]
    )
    r_base = base.index_select(0, owner) + off_r * buffer.row_stride + off_c
    r_face = face.index_select(0, owner)
    r_setup = owner + first
    # A bounded number of rows at a time keeps memory flat whatever the triangles' sizes.
    ends = torch.cumsum(r_rows, 0).tolist()
    limit = max(1, max_pairs // REGION)
    lo = 0
    while lo < len(ends):
        hi = max(lo + 1, bisect.bisect_right(ends, (ends[lo - 1] if lo else 0) + limit))
        regions = Entries(r_params[:, lo:hi], r_base[lo:hi], r_face[lo:hi], r_setup[lo:hi])
        draw_spans(buffer, regions, r_rows[lo:hi], r_cols[lo:hi], max_pairs)
        lo = hi


def _draw_vectorised(
    buffer: DepthBuffer, corners: torch.Tensor, triangles: int, resolution, cull_backfaces: bool, max_pairs: int
):
    """Draw every (view, triangle) pair of ``corners`` (4,3,N) into ``buffer`` with the vectorised
    passes (CUDA, or the CPU without the compiled loop of :mod:`mesh2tex.render.kernels`).

    Returns:
        live (L,) int64 (view * T + triangle), row0, col0 (L,) int64 box origins, params64 (12,L)
        float64 planes relative to them, front (L,) bool: the set-ups that can draw.
    """
    setups = _live_setup(corners, resolution, cull_backfaces)
    live, counts = setups.live, setups.counts
    if live.numel():
        face, view = live % triangles, torch.div(live, triangles, rounding_mode="floor")
        base = view * (buffer.shape[1] * buffer.row_stride) + setups.row0 * buffer.row_stride + setups.col0
        # Boxes of at most WHOLE x WHOLE pixels are drawn whole, bin by bin; larger ones (sorted
        # last) go through the coarse pass.
        n = sum(counts[:N_BINS])
        if n:
            entries = Entries(
                _scaled(setups.params64[:, :n], setups.scale[:, :n]),
                base[:n],
                face[:n],
                torch.arange(n, device=live.device),
            )
            draw(buffer, entries, bin_slices(counts[:N_BINS], max_pairs), max_pairs)
        if counts[N_BINS]:
            _draw_large(buffer, setups, n, base[n:], face[n:], max_pairs)
    return live, setups.row0, setups.col0, setups.params64, setups.front


def resolve_winners(raster: Raster, keys: torch.Tensor, id_bits: int, triangles: int, live, row0, col0, params64):
    """Fill ``raster`` in place from visibility keys: each covered pixel's winner gets its exact
    barycentrics and depth, from the float64 set-up (so they are not quantised).

    Args:
        raster: Raster of (B,H,W) background values.
        keys: (B*H*W,) int64 keys (:class:`~mesh2tex.render.binning.DepthBuffer`), int64 max: empty.
        triangles: T, the triangles per view.
        live: (L,) int64 (view * T + triangle) of each set-up; row0, col0: (L,) its box origin;
        params64: (12,L) float64 planes relative to the box origin.
    """
    B, H, W = raster.face_id.shape
    covered = torch.nonzero(keys != torch.iinfo(torch.long).max).squeeze(1)
    if covered.numel() == 0:
        return
    triangle = keys.index_select(0, covered) & ((1 << id_bits) - 1)
    view = torch.div(covered, H * W, rounding_mode="floor")
    # (view, triangle) -> index of its set-up among the live ones.
    lookup = torch.full((B * triangles,), -1, dtype=torch.long, device=keys.device)
    lookup[live] = torch.arange(live.numel(), device=keys.device)
    winner = lookup.index_select(0, view * triangles + triangle)
    in_view = covered % (H * W)
    dr = (torch.div(in_view, W, rounding_mode="floor") - row0.index_select(0, winner)).double()
    dc = (in_view % W - col0.index_select(0, winner)).double()
    p = columns(params64, winner)  # (12,n) float64
    lam = [torch.addcmul(torch.addcmul(p[k], p[k + 4], dc), p[k + 8], dr) for k in range(3)]
    z = torch.addcmul(torch.addcmul(p[3], p[7], dc), p[11], dr)
    inv_sum = 1.0 / (lam[0] + lam[1] + lam[2])
    raster.face_id.view(-1).index_copy_(0, covered, triangle)
    raster.bary.view(-1, 3).index_copy_(0, covered, (torch.stack(lam, dim=1) * inv_sum[:, None]).float())
    raster.depth.view(-1).index_copy_(0, covered, z.float())


def rasterize(
    pos: torch.Tensor,
    tri: torch.Tensor,
    resolution,
    cull_backfaces: bool = False,
    max_pairs: int = DEFAULT_MAX_PAIRS,
) -> Raster:
    """Rasterize triangles given in clip space.

    Args:
        pos: (B,V,4) or (V,4) float, OpenGL clip-space vertex positions (see ``transform_points``).
            The set-up runs in float64 from these values: float64 positions give barycentrics exact
            to ~1e-6 even on nearly edge-on triangles, where float32 rounding of ``pos`` itself
            limits them to ~1e-3.
        tri: (T,3) int, vertex indices; shared by all B views.
        resolution: (H, W). Pixel (row i, column j) has its centre at NDC
            x = (2j+1)/W - 1, y = 1 - (2i+1)/H: row 0 is the top of the image.
        cull_backfaces: drop triangles that are clockwise in NDC (OpenGL's default front face is
            counter-clockwise). Off by default: both sides are drawn.
        max_pairs: at most this many candidate (triangle, pixel) pairs are held at once by the vectorised
            passes; bounds memory (the compiled CPU loop holds none).
    Returns:
        Raster with ``face_id`` (B,H,W) int64, ``bary`` (B,H,W,3) float32, ``depth`` (B,H,W) float32,
        on the device of ``pos``. The nearest surface (smallest NDC z) wins; surface points outside
        -1 <= z <= 1 (in front of the near plane or beyond the far plane) are not drawn.
    """
    check_shape(pos, "rasterize: pos", ("B", "V", 4), ("V", 4), dtype="float")
    check_shape(tri, "rasterize: tri", ("T", 3), dtype="int")
    if not hasattr(resolution, "__len__") or len(resolution) != 2:
        raise ValueError(f"rasterize: resolution must be (H, W), got {resolution!r}")
    H, W = int(resolution[0]), int(resolution[1])
    with torch.no_grad():
        if pos.dim() == 2:
            pos = pos[None]
        B, device = pos.shape[0], pos.device
        tri = tri.to(device=device, dtype=torch.long)
        T = tri.shape[0]
        face_id = torch.full((B, H, W), -1, dtype=torch.long, device=device)
        bary = torch.zeros((B, H, W, 3), dtype=torch.float32, device=device)
        depth = torch.ones((B, H, W), dtype=torch.float32, device=device)
        if T == 0 or B == 0:
            return Raster(face_id, bary, depth)

        raster = Raster(face_id, bary, depth)
        buffer = DepthBuffer(B, (H, W), (WHOLE, WHOLE), T, device)
        drawn = None
        if device.type == "cpu" and pos.dtype in (torch.float32, torch.float64) and kernels.available():
            drawn = kernels.rasterize_views(pos, tri, (H, W), cull_backfaces, buffer)
        if drawn is None:  # no loop, or it stopped at a triangle across the near plane: the keys it wrote are
            # ones the vectorised passes write again (a depth test keeps the minimum), so the result is the same
            corners = gather_corners(pos, tri)
            live, row0, col0, params64, front = _draw_vectorised(buffer, corners, T, (H, W), cull_backfaces, max_pairs)
        else:
            live, row0, col0, params64, front = drawn
        edges = EdgeTest(pos, tri, live, front, (H, W))
        # The few pixels the float32 edge values leave undecided (on an edge, or a small fraction
        # of a pixel from one), all at once.
        buffer.settle(edges)
        resolve_winners(raster, buffer.image((H, W)), buffer.id_bits, T, live, row0, col0, params64)
        return raster
