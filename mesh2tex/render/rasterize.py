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
     candidate pixels. Candidate (triangle, pixel) pairs are enumerated with cumsum/repeat_interleave,
     in chunks of at most ``max_pairs`` so memory stays bounded whatever the triangle sizes.
  3. Visibility: one ``scatter_reduce('amin')`` per chunk over an int64 key per covered pair, the
     quantised depth in the high bits and the triangle's index in the low bits. Ties go to the lower
     triangle index, so results are deterministic.
  4. Only the winning triangle of each pixel gets its barycentrics and depth computed (float64, cast to
     float32), so they are not quantised.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

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
    xj, yj, wj = (t.roll(-1, 0) for t in (x, y, w))  # vertex i+1
    xk, yk, wk = (t.roll(-2, 0) for t in (x, y, w))  # vertex i+2
    # coeff[c, i]: lambda_i = coeff[0, i] * x_ndc + coeff[1, i] * y_ndc + coeff[2, i]; row 3 is z_ndc.
    # Unnormalised, lambda_i's coefficients are e_i = v_j x v_k over (x, y, w): the adjugate of [v0 v1 v2].
    coeff = torch.empty(3, 4, clip.shape[2], dtype=clip.dtype, device=clip.device)
    torch.sub(yj * wk, wj * yk, out=coeff[0, :3])
    torch.sub(wj * xk, xj * wk, out=coeff[1, :3])
    torch.sub(xj * yk, yj * xk, out=coeff[2, :3])
    det = x[0] * coeff[0, 0] + y[0] * coeff[1, 0] + w[0] * coeff[2, 0]
    coeff[:, :3] /= det
    torch.sum(coeff[:, :3] * z, dim=1, out=coeff[:, 3])
    ref_x = (2 * col0 + 1).to(clip.dtype) / W - 1
    ref_y = 1 - (2 * row0 + 1).to(clip.dtype) / H
    params = torch.empty(3, 4, clip.shape[2], dtype=clip.dtype, device=clip.device)
    torch.addcmul(torch.addcmul(coeff[2], coeff[0], ref_x), coeff[1], ref_y, out=params[0])
    torch.mul(coeff[0], 2.0 / W, out=params[1])
    torch.mul(coeff[1], -2.0 / H, out=params[2])
    return params.view(12, -1), det


# Boxes are split into tiles of at most _TILE x _TILE pixels (a power of two) before binning.
_TILE = 64


def _select_columns(table: torch.Tensor, index: torch.Tensor) -> list[torch.Tensor]:
    """Columns ``index`` of a (K,N) table as K tensors (n,); row by row is much faster on CPU than
    ``index_select`` along dim 1."""
    return [row.index_select(0, index) for row in table]


def _tile_entries(params, view, row0, col0, rows, cols, resolution):
    """Split every live triangle's pixel box into tiles of at most _TILE x _TILE pixels.

    Args:
        params: (12,N) float64 from :func:`_edge_setup`, relative to each box origin.
        view: (N,) int64 view index; row0, col0, rows, cols: (N,) int64 boxes.
    Returns:
        dict of per-entry tensors: owner (E,) index into N; base_pixel (E,) flat index into B*H*W of
        the entry's origin; rows, cols (E,) its size; params (12,E) float32 rebased to its origin.
    """
    H, W = resolution
    device = rows.device
    tiles_r = (rows + _TILE - 1) // _TILE
    tiles_c = (cols + _TILE - 1) // _TILE
    n_tiles = tiles_r * tiles_c
    if bool((n_tiles == 1).all()):
        return {
            "owner": torch.arange(rows.numel(), device=device),
            "base_pixel": view * (H * W) + row0 * W + col0,
            "rows": rows,
            "cols": cols,
            "params": params.float(),
        }
    owner = torch.repeat_interleave(torch.arange(rows.numel(), device=device), n_tiles)
    k = torch.arange(owner.numel(), device=device) - (torch.cumsum(n_tiles, 0) - n_tiles)[owner]
    per_row = tiles_c[owner]
    off_r = torch.div(k, per_row, rounding_mode="floor") * _TILE
    off_c = (k % per_row) * _TILE
    entry_params = torch.stack(_select_columns(params, owner))
    if bool(off_r.any() | off_c.any()):
        entry_params[0:4] += entry_params[4:8] * off_c.double() + entry_params[8:12] * off_r.double()
    r0, c0 = row0[owner] + off_r, col0[owner] + off_c
    return {
        "owner": owner,
        "base_pixel": view[owner] * (H * W) + r0 * W + c0,
        "rows": (rows[owner] - off_r).clamp(max=_TILE),
        "cols": (cols[owner] - off_c).clamp(max=_TILE),
        "params": entry_params.float(),
    }


def _binned(entries, max_pairs):
    """Group entries by their box size rounded up to powers of two, in chunks of bounded size.

    Yields:
        (cap_rows, cap_cols, index) with index (n,) int64 into the entries, n * cap_rows * cap_cols
        at most max_pairs (at least one entry per chunk).
    """
    # ceil(log2(size)) is the binary length of size - 1.
    row_bits = torch.frexp((entries["rows"] - 1).float()).exponent.long()
    col_bits = torch.frexp((entries["cols"] - 1).float()).exponent.long()
    n_bits = _TILE.bit_length()
    bin_id = row_bits * n_bits + col_bits
    order = torch.argsort(bin_id, stable=True)
    sizes = torch.bincount(bin_id, minlength=n_bits * n_bits).tolist()
    start = 0
    for b, size in enumerate(sizes):
        if size == 0:
            continue
        cap_rows, cap_cols = 1 << (b // n_bits), 1 << (b % n_bits)
        step = max(1, max_pairs // (cap_rows * cap_cols))
        for lo in range(start, start + size, step):
            yield cap_rows, cap_cols, order[lo:min(start + size, lo + step)]
        start += size


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

        # Component-major layout (4,B,3,T) so that every per-triangle quantity is a contiguous row.
        by_component = pos.detach().permute(2, 0, 1).reshape(-1)  # (4*B*V,)
        row_start = torch.arange(4 * B, device=device)[:, None] * V
        corners = by_component.index_select(0, (row_start + tri.T.reshape(1, -1)).reshape(-1))
        corners = corners.view(4, B, 3, T)
        row0, col0, rows, cols = _pixel_boxes(corners.float(), (H, W))
        live = torch.nonzero((rows * cols).reshape(-1)).squeeze(1)  # index into B*T
        row0, col0, rows, cols = (t.reshape(-1).index_select(0, live) for t in (row0, col0, rows, cols))
        view, face = live // T, live % T
        slot = (torch.arange(4, device=device)[:, None] * (B * 3) + torch.arange(3, device=device)) * T
        index = slot[:, :, None] + (view * (3 * T) + face)  # (4,3,N) into corners
        live_clip = corners.reshape(-1).index_select(0, index.reshape(-1)).view(4, 3, -1).double()
        params, det = _edge_setup(live_clip, (H, W), row0, col0)
        keep = torch.isfinite(1.0 / det)  # degenerate triangles (seen edge-on, or through the eye)
        if cull_backfaces:
            keep &= det > 0
        dropped = live.numel() - int(keep.sum())
        if dropped > live.numel() // 8:  # worth compacting (culling): keep only the rest
            kept = torch.nonzero(keep).squeeze(1)
            live, view, row0, col0, rows, cols = (
                t.index_select(0, kept) for t in (live, view, row0, col0, rows, cols))
            params = torch.stack(_select_columns(params, kept))
        elif dropped:  # a few: NaN fails every coverage test
            params[0] = torch.where(keep, params[0], torch.full_like(params[0], float("nan")))
        n_live = live.numel()
        if n_live == 0:
            return Raster(face_id, bary, depth)
        # Visibility key: quantised depth (high bits) | live index (low bits).
        id_bits = max(1, int(n_live).bit_length())
        depth_scale = 0.5 * float((1 << min(62 - id_bits, 40)) - 1)
        empty = torch.iinfo(torch.long).max
        best = torch.full((B * H * W,), empty, dtype=torch.long, device=device)

        entries = _tile_entries(params, view, row0, col0, rows, cols, (H, W))
        for cap_rows, cap_cols, chunk in _binned(entries, max_pairs):
            owner, base_pixel, box_rows, box_cols = (entries[k].index_select(0, chunk) for k in (
                "owner", "base_pixel", "rows", "cols"))
            p = _select_columns(entries["params"], chunk)
            row_steps = torch.arange(cap_rows, device=device, dtype=torch.float32)
            col_steps = torch.arange(cap_cols, device=device, dtype=torch.float32)

            def plane(ref, step_c, step_r):  # an affine function over the (n, rows, cols) grid
                per_row = torch.addcmul(p[ref][:, None], p[step_r][:, None], row_steps)
                return torch.addcmul(per_row[:, :, None], p[step_c][:, None, None], col_steps)

            lam_min = torch.minimum(torch.minimum(plane(0, 4, 8), plane(1, 5, 9)), plane(2, 6, 10))
            inside = lam_min >= 0
            z = plane(3, 7, 11)
            inside &= z.abs() <= 1  # between the near and far planes
            inside &= (row_steps[:, None] < box_rows[:, None, None]) & (col_steps < box_cols[:, None, None])
            hit = torch.nonzero(inside.view(-1)).squeeze(1)
            if hit.numel() == 0:
                continue
            row_bits, col_bits = cap_rows.bit_length() - 1, cap_cols.bit_length() - 1
            entry = hit >> (row_bits + col_bits)
            dr = (hit >> col_bits) & (cap_rows - 1)
            dc = hit & (cap_cols - 1)
            pixel = base_pixel.index_select(0, entry) + dr * W + dc
            quantised = ((z.view(-1).index_select(0, hit).double() + 1) * depth_scale).long()
            key = (quantised << id_bits) | owner.index_select(0, entry)
            best.scatter_reduce_(0, pixel, key, reduce="amin", include_self=True)

        covered = torch.nonzero(best != empty).squeeze(1)
        if covered.numel() == 0:
            return Raster(face_id, bary, depth)
        winner = best.index_select(0, covered) & ((1 << id_bits) - 1)
        # Exact barycentrics and depth of the winner only, from the float64 set-up.
        in_view = covered % (H * W)
        dr = (torch.div(in_view, W, rounding_mode="floor") - row0.index_select(0, winner)).double()
        dc = (in_view % W - col0.index_select(0, winner)).double()
        p = _select_columns(params, winner)  # 12 x (n,) float64
        lam = [torch.addcmul(torch.addcmul(p[k], p[k + 4], dc), p[k + 8], dr) for k in range(3)]
        z = torch.addcmul(torch.addcmul(p[3], p[7], dc), p[11], dr)
        inv_sum = 1.0 / (lam[0] + lam[1] + lam[2])
        face_id.view(-1).index_copy_(0, covered, live.index_select(0, winner) % T)
        bary.view(-1, 3).index_copy_(0, covered, (torch.stack(lam, dim=1) * inv_sum[:, None]).float())
        depth.view(-1).index_copy_(0, covered, z.float())
        return Raster(face_id, bary, depth)
