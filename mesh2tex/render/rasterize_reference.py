"""A slow, direct rasterizer that defines what :func:`mesh2tex.render.rasterize` computes; for tests.

It shares the boxes, the float64 set-up, the regions and the winners' barycentrics with the fast
path, and replaces everything the fast path does for speed (size bins, stencils, the coarse pass
by row spans with pixels taken without tests, chunks, the padded buffer) by a loop over regions, one
at a time, each tested at every pixel of its rectangle with the same float32 arithmetic and written
into a depth buffer with ``minimum``. The two must agree bit for bit.
"""

from __future__ import annotations

import torch

from mesh2tex.checks import check_shape
from mesh2tex.render.binning import DepthBuffer
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
        raster = Raster(torch.full((B, H, W), -1, dtype=torch.long, device=device),
                        torch.zeros((B, H, W, 3), dtype=torch.float32, device=device),
                        torch.ones((B, H, W), dtype=torch.float32, device=device))
        if T == 0 or B == 0:
            return raster
        corners = gather_corners(pos, tri.to(device=device, dtype=torch.long))
        live, row0, col0, rows, cols, params64, _ = _live_setup(corners, (H, W), cull_backfaces)
        buffer = DepthBuffer(B, (H, W), (0, 0), T, device)
        keys = buffer.keys.view(B, H, W)
        owner, off_r, off_c, r_rows, r_cols, r_params = _regions(params64, rows, cols)
        for k in range(owner.numel()):
            i = int(owner[k])
            view, face = divmod(int(live[i]), T)
            top, left = int(row0[i] + off_r[k]), int(col0[i] + off_c[k])
            n_rows, n_cols = min(int(r_rows[k]), H - top), min(int(r_cols[k]), W - left)
            p = r_params[:, k]
            dr = torch.arange(n_rows, device=device, dtype=torch.float32)[:, None]
            dc = torch.arange(n_cols, device=device, dtype=torch.float32)

            def plane(j):  # p[j] + p[j + 8] * dr + p[j + 4] * dc, rounded as the fast path does
                return torch.addcmul(torch.addcmul(p[j], p[j + 8], dr), p[j + 4], dc)

            covered = (plane(0) >= 0) & (plane(1) >= 0) & (plane(2) >= 0)
            z = plane(3)
            key = (((z.double() + 1) * buffer.depth_scale).long() << buffer.id_bits) | face
            key = torch.where(covered & (z.abs() <= 1), key, buffer.empty)
            window = keys[view, top:top + n_rows, left:left + n_cols]
            torch.minimum(window, key, out=window)
        resolve_winners(raster, buffer.keys, buffer.id_bits, T, live, row0, col0, params64)
        return raster
