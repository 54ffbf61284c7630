"""A vectorised triangle rasterizer in pure PyTorch (CPU and CUDA, no compiled extension).

Method (homogeneous rasterization, no geometric clipping):
  1. Per triangle, the 2D-homogeneous edge functions ``lambda_i(p) = e_i . (x, y, 1) / det`` with
     ``e_i = v_j x v_k`` over the clip-space columns ``v = (x, y, w)``. For a pixel centre p they equal
     the perspective-correct barycentrics divided by the clip w of the surface point, so
     ``bary = lambda / sum(lambda)``, ``1 / w = sum(lambda)`` and NDC ``z = sum(lambda_i z_i)`` is affine
     in screen space. A pixel is covered when every ``lambda_i >= 0`` (which also puts the surface point
     in front of the camera, w > 0) and ``-1 <= z <= 1`` (near and far planes, tested per pixel). This
     is exact for triangles that cross the near plane or reach behind the camera: no garbage, no
     clipping into new triangles. The set-up runs in float64; the per-pixel tests in float32 relative to
     a reference pixel, so nothing cancels catastrophically.
  2. Per triangle and view, a pixel bounding box (of the triangle clipped to the near plane) gives the
     candidate pixels. Boxes are sorted into bins by their size rounded up to powers of two (boxes
     over 64 pixels a side are first split into tiles), so each bin is a contiguous slice evaluated as
     a dense (n, rows, cols) grid of edge functions, in chunks of at most ``max_pairs`` candidates so
     memory stays bounded whatever the triangle sizes. The visibility buffer is padded by the largest
     stencil, so stencil pixels past the image edge need no test; depth is computed at hits only.
  3. Visibility: one ``scatter_reduce('amin')`` per chunk over an int64 key per covered pair, the
     quantised depth in the high bits and the triangle's index in the low bits. Ties go to the lower
     triangle index, so results are deterministic.
  4. Only the winning triangle of each pixel gets its barycentrics and depth computed (float64, cast to
     float32), so they are not quantised.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from mesh2tex.checks import check_shape

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


def pixel_centers(resolution, device=None, dtype=torch.float32) -> torch.Tensor:
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
            (x_min, torch.where(valid, px, inf).amin(1)), (x_max, torch.where(valid, px, -inf).amax(1)),
            (y_min, torch.where(valid, py, inf).amin(1)), (y_max, torch.where(valid, py, -inf).amax(1)),
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



# Boxes larger than _TILE x _TILE pixels (rare: big triangles on screen) are split into tiles of at
# most that size (a power of two); every other box is evaluated whole.
_TILE = 64
_N_BITS = _TILE.bit_length()  # log2 of a power-of-two cap is in [0, _N_BITS)


def _size_bins(rows: torch.Tensor, cols: torch.Tensor) -> torch.Tensor:
    """Bin of each box: its size rounded up to powers of two, ``row_bits * _N_BITS + col_bits``.

    Args:
        rows, cols: (N,) int64 box sizes in [1, _TILE].
    Returns:
        (N,) int64 bin ids in [0, _N_BITS**2).
    """
    # ceil(log2(size)) is the binary length of size - 1.
    row_bits = torch.frexp((rows - 1).float()).exponent.long()
    col_bits = torch.frexp((cols - 1).float()).exponent.long()
    return row_bits * _N_BITS + col_bits


# Launch overhead of one bin, in candidate pixels of work: consecutive bins are merged into one
# stencil (the largest of their caps) while the padding this adds costs less than that.
_BIN_OVERHEAD_PAIRS = 16384


def _bin_slices(counts: list[int], max_pairs: int):
    """Chunks of entries sorted by bin: ``(cap_rows, cap_cols, lo, hi)`` with at most ``max_pairs``
    candidate pixels each (at least one entry).

    Consecutive non-empty bins share one stencil when that is cheaper than a launch of their own;
    any stencil at least as large as an entry's box gives the same result.
    """
    groups = []  # [row_bits, col_bits, lo, hi, own_pairs]
    start = 0
    for b, size in enumerate(counts):
        if size == 0:
            continue
        rb, cb = b // _N_BITS, b % _N_BITS
        own = size << (rb + cb)
        if groups:
            g = groups[-1]
            merged_rb, merged_cb = max(g[0], rb), max(g[1], cb)
            waste = ((g[3] - g[2] + size) << (merged_rb + merged_cb)) - g[4] - own
            if waste < _BIN_OVERHEAD_PAIRS:
                g[0], g[1], g[3], g[4] = merged_rb, merged_cb, start + size, g[4] + own
                start += size
                continue
        groups.append([rb, cb, start, start + size, own])
        start += size
    for rb, cb, lo, hi, _ in groups:
        step = max(1, max_pairs >> (rb + cb))
        for chunk_lo in range(lo, hi, step):
            yield 1 << rb, 1 << cb, chunk_lo, min(hi, chunk_lo + step)


def _draw_bins(best, params, base_pixel, face, slices, row_stride, id_bits, depth_scale, max_pairs):
    """Depth-test every candidate pixel of the entries in ``slices`` into ``best``.

    Each chunk of entries shares a power-of-two stencil (cap_rows, cap_cols) and is evaluated as a
    dense (n, cap_rows, cap_cols) grid of edge functions, with no per-pixel gathers. Stencil pixels
    outside an entry's box need no test of their own: only pixels inside the triangle pass, and
    ``best`` is padded so that stencils running past the image's right or bottom edge stay in it.
    The hits of several chunks (at most about ``max_pairs``) are depth-tested together.

    Args:
        best: (B*Hp*Wp,) int64 visibility keys of the padded image, updated in place.
        params: (E,12) float32 edge and depth planes of each entry, relative to its origin pixel.
        base_pixel: (E,) int64 flat index into ``best`` of each entry's origin pixel.
        face: (E,) int64 triangle index of each entry (the key's low bits).
        slices: (cap_rows, cap_cols, lo, hi) chunks from :func:`_bin_slices`.
        row_stride: Wp, the padded image width.
    """
    device = best.device
    hits = []  # (entry, row offset, column offset) per chunk

    def depth_test():
        entry, dr, dc = (torch.cat(t) for t in zip(*hits))
        hits.clear()
        # Depth at the hits only, with the same arithmetic as a dense plane.
        q = params.index_select(0, entry)
        z = torch.addcmul(torch.addcmul(q[:, 3], q[:, 11], dr.float()), q[:, 7], dc.float())
        pixel = base_pixel.index_select(0, entry) + dr * row_stride + dc
        key = (((z.double() + 1) * depth_scale).long() << id_bits) | face.index_select(0, entry)
        key = torch.where(z.abs() <= 1, key, torch.iinfo(torch.long).max)  # near and far planes
        best.scatter_reduce_(0, pixel, key, reduce="amin", include_self=True)

    pending = 0
    for cap_rows, cap_cols, lo, hi in slices:
        p = params[lo:hi]
        row_steps = torch.arange(cap_rows, device=device, dtype=torch.float32)
        col_steps = torch.arange(cap_cols, device=device, dtype=torch.float32)

        def plane(ref, step_c, step_r):  # an affine function over the (n, rows, cols) grid
            per_row = torch.addcmul(p[:, ref, None], p[:, step_r, None], row_steps)
            return torch.addcmul(per_row[:, :, None], p[:, step_c, None, None], col_steps)

        lam_min = torch.minimum(torch.minimum(plane(0, 4, 8), plane(1, 5, 9)), plane(2, 6, 10))
        hit = torch.nonzero(lam_min.view(-1) >= 0).squeeze(1)
        row_bits, col_bits = cap_rows.bit_length() - 1, cap_cols.bit_length() - 1
        hits.append(((hit >> (row_bits + col_bits)) + lo, (hit >> col_bits) & (cap_rows - 1),
                     hit & (cap_cols - 1)))
        pending += (hi - lo) * cap_rows * cap_cols
        if pending >= max_pairs:
            depth_test()
            pending = 0
    if hits:
        depth_test()


def _tiles(params64, row0, col0, rows, cols):
    """Split boxes into tiles of at most _TILE x _TILE pixels.

    Args:
        params64: (12,N) float64 from :func:`_edge_setup`, relative to each box origin.
        row0, col0, rows, cols: (N,) int64 boxes.
    Returns:
        owner (E,) index into N; row0, col0, rows, cols (E,) of each tile; params (E,12) float32
        rebased (in float64) to the tile's origin.
    """
    device = rows.device
    tiles_r = (rows + _TILE - 1) // _TILE
    tiles_c = (cols + _TILE - 1) // _TILE
    n_tiles = tiles_r * tiles_c
    owner = torch.repeat_interleave(torch.arange(rows.numel(), device=device), n_tiles)
    k = torch.arange(owner.numel(), device=device) - (torch.cumsum(n_tiles, 0) - n_tiles)[owner]
    per_row = tiles_c[owner]
    off_r = torch.div(k, per_row, rounding_mode="floor") * _TILE
    off_c = (k % per_row) * _TILE
    p = params64[:, owner]
    p[0:4] += p[4:8] * off_c.double() + p[8:12] * off_r.double()
    return (owner, row0[owner] + off_r, col0[owner] + off_c, (rows[owner] - off_r).clamp(max=_TILE),
            (cols[owner] - off_c).clamp(max=_TILE), p.T.float().contiguous())


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
        max_pairs: at most this many candidate (triangle, pixel) pairs are held at once; bounds memory.
    Returns:
        Raster with ``face_id`` (B,H,W) int64, ``bary`` (B,H,W,3) float32, ``depth`` (B,H,W) float32,
        on the device of ``pos``. The nearest surface (smallest NDC z) wins; surface points outside
        -1 <= z <= 1 (in front of the near plane or beyond the far plane) are not drawn.
    """
    check_shape(pos, "rasterize: pos", ("B", "V", 4), ("V", 4))
    check_shape(tri, "rasterize: tri", ("T", 3))
    if len(resolution) != 2:
        raise ValueError(f"rasterize: resolution must be (H, W), got {tuple(resolution)}")
    H, W = int(resolution[0]), int(resolution[1])
    with torch.no_grad():
        if pos.dim() == 2:
            pos = pos[None]
        B, V, device = pos.shape[0], pos.shape[1], pos.device
        tri = tri.to(device=device, dtype=torch.long)
        T = tri.shape[0]
        face_id = torch.full((B, H, W), -1, dtype=torch.long, device=device)
        bary = torch.zeros((B, H, W, 3), dtype=torch.float32, device=device)
        depth = torch.ones((B, H, W), dtype=torch.float32, device=device)
        if T == 0 or B == 0:
            return Raster(face_id, bary, depth)

        # Component-major layout (4,3,B*T): every per-(view, triangle) quantity is a contiguous row.
        by_component = pos.detach().permute(2, 0, 1).reshape(-1)  # (4*B*V,)
        index = (torch.arange(4, device=device)[:, None, None, None] * (B * V)
                 + torch.arange(B, device=device)[:, None] * V + tri.T[:, None, :])
        corners = by_component.index_select(0, index.reshape(-1)).view(4, 3, B * T)
        row0, col0, rows, cols = (t.view(-1) for t in _pixel_boxes(corners.float()[:, None], (H, W)))
        params64, det = _edge_setup(corners.double(), (H, W), row0, col0)  # (12,B*T)
        # Degenerate triangles (seen edge-on, or through the eye) and culled ones draw nothing.
        live = (rows * cols > 0) & torch.isfinite(1.0 / det)
        if cull_backfaces:
            live &= det > 0
        big = (rows > _TILE) | (cols > _TILE)
        # Sort the live boxes by size bin; the big ones (tiled below) and the rest go last.
        n_bins = _N_BITS * _N_BITS
        bin_id = torch.where(big, n_bins, _size_bins(rows.clamp(1, _TILE), cols.clamp(1, _TILE)))
        bin_id = torch.where(live, bin_id, n_bins + 1)
        order = torch.argsort(bin_id, stable=True)
        counts = torch.bincount(bin_id, minlength=n_bins + 2).tolist()
        n_small, n_big = sum(counts[:n_bins]), counts[n_bins]
        if n_small + n_big == 0:
            return Raster(face_id, bary, depth)
        # Rows of (view, triangle) set-ups, for gathers of a few triangles' every parameter.
        by_triangle = torch.stack(list(params64), dim=1)  # (B*T,12) float64
        view = torch.arange(B, device=device).repeat_interleave(T)

        # Visibility key: quantised depth (high bits) | triangle index (low bits), so that ties go
        # to the lower index. ``best`` is padded by the largest stencil in use.
        id_bits = max(1, int(T).bit_length())
        depth_scale = 0.5 * float((1 << min(62 - id_bits, 40)) - 1)
        empty = torch.iinfo(torch.long).max
        used = [b for b in range(n_bins) if counts[b]]
        pad_r = _TILE if n_big else 1 << (max(b // _N_BITS for b in used) if used else 0)
        pad_c = _TILE if n_big else 1 << (max(b % _N_BITS for b in used) if used else 0)
        Hp, Wp = H + pad_r, W + pad_c
        best = torch.full((B * Hp * Wp,), empty, dtype=torch.long, device=device)

        small = order[:n_small]
        base_pixel = view * (Hp * Wp) + row0 * Wp + col0  # (B*T,)
        _draw_bins(best, by_triangle.index_select(0, small).float(), base_pixel.index_select(0, small),
                   small % T, _bin_slices(counts[:n_bins], max_pairs), Wp, id_bits, depth_scale, max_pairs)
        if n_big:
            large = order[n_small:n_small + n_big]
            owner, t_row0, t_col0, t_rows, t_cols, t_params = _tiles(
                params64[:, large], *(t.index_select(0, large) for t in (row0, col0, rows, cols)))
            t_bin = _size_bins(t_rows, t_cols)
            t_order = torch.argsort(t_bin, stable=True)
            t_counts = torch.bincount(t_bin, minlength=n_bins).tolist()
            t_large = large.index_select(0, owner.index_select(0, t_order))
            t_base = (view.index_select(0, t_large) * (Hp * Wp) + t_row0.index_select(0, t_order) * Wp
                      + t_col0.index_select(0, t_order))
            _draw_bins(best, t_params.index_select(0, t_order), t_base, t_large % T,
                       _bin_slices(t_counts, max_pairs), Wp, id_bits, depth_scale, max_pairs)

        best = best.view(B, Hp, Wp)[:, :H, :W].reshape(-1)
        covered = torch.nonzero(best != empty).squeeze(1)
        if covered.numel() == 0:
            return Raster(face_id, bary, depth)
        winner = (best.index_select(0, covered) & ((1 << id_bits) - 1))
        winner += torch.div(covered, H * W, rounding_mode="floor") * T  # index into B*T
        # Exact barycentrics and depth of the winner only, from the float64 set-up.
        in_view = covered % (H * W)
        dr = (torch.div(in_view, W, rounding_mode="floor") - row0.index_select(0, winner)).double()
        dc = (in_view % W - col0.index_select(0, winner)).double()
        p = by_triangle.index_select(0, winner)  # (n,12) float64
        lam = [torch.addcmul(torch.addcmul(p[:, k], p[:, k + 4], dc), p[:, k + 8], dr) for k in range(3)]
        z = torch.addcmul(torch.addcmul(p[:, 3], p[:, 7], dc), p[:, 11], dr)
        inv_sum = 1.0 / (lam[0] + lam[1] + lam[2])
        face_id.view(-1).index_copy_(0, covered, winner % T)
        bary.view(-1, 3).index_copy_(0, covered, (torch.stack(lam, dim=1) * inv_sum[:, None]).float())
        depth.view(-1).index_copy_(0, covered, z.float())
        return Raster(face_id, bary, depth)
