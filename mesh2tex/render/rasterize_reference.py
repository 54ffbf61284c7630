"""A slow, direct rasterizer that defines what :func:`mesh2tex.render.rasterize` computes; for tests.

It shares the boxes, the float64 set-up, the regions, the exact edge test and the winners'
barycentrics with the fast path, and replaces everything the fast path does for speed (the float32
edge planes and their band, size bins, stencils, the coarse pass by row spans with pixels taken
without tests, chunks, the padded buffer) by a loop over regions, one at a time: every pixel of a
region's rectangle is decided by the exact edge test (:class:`~mesh2tex.render.edges.EdgeTest`),
its depth computed with the same float32 arithmetic, and written into a depth buffer with
``minimum``. The two must agree bit for bit: the fast path's float32 filter must never decide a
pixel the exact test decides otherwise.
"""

from __future__ import annotations

import torch

from mesh2tex.checks import check_shape
from mesh2tex.render.binning import DepthBuffer
from mesh2tex.render.edges import EdgeTest
from mesh2tex.render.rasterize import Raster, _live_setup, _regions, gather_corners, resolve_winners


def rasterize_reference(pos: torch.Tensor, tri: torch.Tensor, resolution, cull_backfaces: bool = False) -> Raster:
    """Same arguments and result as :func:`mesh2tex.render.rasterize` (without ``max_pairs``).

    Args:
        pos: (B,V,4) or (V,4) float clip-space vertex positions.
        tri: (T,3) int vertex indices.
        resolution: (H, W).
    Returns:
        Raster with ``face_id`` (B,H,W) int64, ``bary`` (B,H,W,3) float32, ``depth`` (B,H,W) float32.
    """
    check_shape(pos, "rasterize_reference: pos", ("B", "V", 4), ("V", 4), dtype="float")
    check_shape(tri, "rasterize_reference: tri", ("T", 3), dtype="int")
    H, W = int(resolution[0]), int(resolution[1])
    with torch.no_grad():
        pos = pos[None] if pos.dim() == 2 else pos
        B, T, device = pos.shape[0], tri.shape[0], pos.device
        raster = Raster(
            torch.full((B, H, W), -1, dtype=torch.long, device=device),
            torch.zeros((B, H, W, 3), dtype=torch.float32, device=device),
            torch.ones((B, H, W), dtype=torch.float32, device=device),
        )
        if T == 0 or B == 0:
            return raster
        tri = tri.to(device=device, dtype=torch.long)
        corners = gather_corners(pos, tri)
        setups = _live_setup(corners, (H, W), cull_backfaces)
        live, row0, col0 = setups.live, setups.row0, setups.col0
        edges = EdgeTest(pos, tri, live, setups.front, (H, W))
        buffer = DepthBuffer(B, (H, W), (0, 0), T, device)
        keys = buffer.keys.view(B, H, W)
        owner, off_r, off_c, r_rows, r_cols, r_params = _regions(
            setups.params64, setups.scale, setups.rows, setups.cols
        )
        for k in range(owner.numel()):
            i = int(owner[k])
            view, face = divmod(int(live[i]), T)
            top, left = int(row0[i] + off_r[k]), int(col0[i] + off_c[k])
            n_rows, n_cols = min(int(r_rows[k]), H - top), min(int(r_cols[k]), W - left)
            p = r_params[:, k]
            dr = torch.arange(n_rows, device=device, dtype=torch.float32)[:, None]
            dc = torch.arange(n_cols, device=device, dtype=torch.float32)
            rows = torch.arange(top, top + n_rows, device=device)[:, None].expand(n_rows, n_cols).reshape(-1)
            cols = torch.arange(left, left + n_cols, device=device).repeat(n_rows)
            covered = edges.inside(torch.full_like(rows, i), rows, cols).view(n_rows, n_cols)
            # p[3] + p[11] * dr + p[7] * dc, rounded as the fast path does
            z = torch.addcmul(torch.addcmul(p[3], p[11], dr), p[7], dc)
            key = (((z.double() + 1) * buffer.depth_scale).long() << buffer.id_bits) | face
            key = torch.where(covered & (z.abs() <= 1), key, buffer.empty)
            window = keys[view, top : top + n_rows, left : left + n_cols]
            torch.minimum(window, key, out=window)
        resolve_winners(raster, buffer.keys, buffer.id_bits, T, live, row0, col0, setups.params64)
        return raster
