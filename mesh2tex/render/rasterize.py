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
_BOX_MARGIN = 1e-4


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


def _triangle_setup(clip: torch.Tensor, resolution, cull_backfaces: bool):
    """Per (view, triangle) edge-function coefficients and candidate pixel boxes.

    Args:
        clip: (B,T,3,4) float64 clip-space vertices of every triangle in every view.
    Returns:
        lam_ref: (B,T,3) lambda at the reference pixel (the box's top-left pixel centre).
        lam_dx, lam_dy: (B,T,3) lambda per NDC unit in x and y.
        z_ref, z_dx, z_dy: (B,T) NDC depth plane, same parametrisation.
        row0, col0, rows, cols: (B,T) int64 box origin and size in pixels (0 size: nothing to draw).
    """
    H, W = resolution
    x, y, z, w = clip.unbind(-1)  # each (B,T,3)
    columns = torch.stack([x, y, w], dim=-1)  # (B,T,3 vertices,3)
    edges = torch.linalg.cross(columns[:, :, [1, 2, 0]], columns[:, :, [2, 0, 1]])  # e_i = v_j x v_k
    det = (columns[:, :, 0] * edges[:, :, 0]).sum(-1)  # (B,T), sign gives the facing
    coeff = edges / det[..., None, None]  # lambda_i = coeff[i] . (x, y, 1)
    z_coeff = (z[..., None] * coeff).sum(-2)  # (B,T,3): z_ndc = z_coeff . (x, y, 1)
    usable = (det != 0) & torch.isfinite(coeff).all(-1).all(-1)
    if cull_backfaces:
        usable &= det > 0  # counter-clockwise in NDC (y up) faces the camera

    # Box of the part of the triangle in front of the near plane (z + w >= 0): the kept vertices plus
    # the points where edges cross the plane.
    dist = z + w  # (B,T,3) signed distance to the near plane (scaled)
    nxt = [1, 2, 0]
    d0, d1 = dist, dist[..., nxt]
    crossing = (d0 * d1) < 0
    t = (d0 / torch.where(crossing, d0 - d1, torch.ones_like(d0))).clamp(0, 1)
    cut = clip + t[..., None] * (clip[:, :, nxt] - clip)  # (B,T,3,4) edge/near-plane intersections
    points = torch.cat([clip, cut], dim=2)  # (B,T,6,4)
    valid = torch.cat([dist >= 0, crossing], dim=2) & (points[..., 3] > 0)
    safe_w = torch.where(valid, points[..., 3], torch.ones_like(points[..., 3]))
    ndc_x = points[..., 0] / safe_w
    ndc_y = points[..., 1] / safe_w
    inf = torch.full_like(ndc_x, float("inf"))
    x_min = torch.where(valid, ndc_x, inf).amin(-1)
    x_max = torch.where(valid, ndc_x, -inf).amax(-1)
    y_min = torch.where(valid, ndc_y, inf).amin(-1)
    y_max = torch.where(valid, ndc_y, -inf).amax(-1)
    usable &= valid.any(-1)

    # NDC -> continuous pixel index whose integers are pixel centres, then the covered integer range.
    col_lo = torch.ceil(((x_min + 1) * W - 1) * 0.5 - _BOX_MARGIN).clamp(0, W)
    col_hi = torch.floor(((x_max + 1) * W - 1) * 0.5 + _BOX_MARGIN).clamp(-1, W - 1)
    row_lo = torch.ceil(((1 - y_max) * H - 1) * 0.5 - _BOX_MARGIN).clamp(0, H)
    row_hi = torch.floor(((1 - y_min) * H - 1) * 0.5 + _BOX_MARGIN).clamp(-1, H - 1)
    usable &= torch.isfinite(x_min) & torch.isfinite(y_min)
    col0, row0 = col_lo.nan_to_num(0).long(), row_lo.nan_to_num(0).long()
    cols = (col_hi.nan_to_num(-1).long() - col0 + 1).clamp(min=0)
    rows = (row_hi.nan_to_num(-1).long() - row0 + 1).clamp(min=0)
    rows = torch.where(usable, rows, torch.zeros_like(rows))

    ref_x = (2 * col0 + 1).double() / W - 1
    ref_y = 1 - (2 * row0 + 1).double() / H
    lam_ref = coeff[..., 0] * ref_x[..., None] + coeff[..., 1] * ref_y[..., None] + coeff[..., 2]
    z_ref = z_coeff[..., 0] * ref_x + z_coeff[..., 1] * ref_y + z_coeff[..., 2]
    return (lam_ref, coeff[..., 0], coeff[..., 1], z_ref, z_coeff[..., 0], z_coeff[..., 1],
            row0, col0, rows, cols)


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
        B, device = pos.shape[0], pos.device
        tri = tri.to(device=device, dtype=torch.long)
        T = tri.shape[0]
        clip = pos.detach().double()[:, tri]  # (B,T,3,4)
        (lam_ref, lam_dx, lam_dy, z_ref, z_dx, z_dy, row0, col0, rows, cols) = _triangle_setup(
            clip, (H, W), cull_backfaces
        )

        # Keep the (view, triangle) entries that have candidate pixels.
        counts = (rows * cols).reshape(-1)
        live = torch.nonzero(counts > 0).squeeze(1)  # index into B*T
        counts = counts[live]
        n_live = live.numel()
        face_id = torch.full((B, H, W), -1, dtype=torch.long, device=device)
        bary = torch.zeros((B, H, W, 3), dtype=torch.float32, device=device)
        depth = torch.ones((B, H, W), dtype=torch.float32, device=device)
        if n_live == 0:
            return Raster(face_id, bary, depth)

        def flat(t):
            return t.reshape(B * T, *t.shape[2:])[live]

        # Per live entry: [lam_ref(3), lam_dx(3), lam_dy(3), z_ref, z_dx, z_dy] in float32, with the
        # NDC step of one pixel folded in so pairs need only integer offsets.
        step_x, step_y = 2.0 / W, -2.0 / H
        params = torch.cat(
            [flat(lam_ref), flat(lam_dx) * step_x, flat(lam_dy) * step_y,
             flat(z_ref)[:, None], flat(z_dx)[:, None] * step_x, flat(z_dy)[:, None] * step_y], dim=1
        )
        params32 = params.float()
        view = live // T
        box_cols = flat(cols)
        base_pixel = view * (H * W) + flat(row0) * W + flat(col0)  # flat pixel index of the box origin

        # Visibility key: quantised depth (high bits) | live index (low bits).
        id_bits = max(1, int(n_live).bit_length())
        depth_levels = float((1 << min(62 - id_bits, 40)) - 1)
        empty = torch.iinfo(torch.long).max
        best = torch.full((B * H * W,), empty, dtype=torch.long, device=device)

        ends = torch.cumsum(counts, 0)
        starts = ends - counts
        total = int(ends[-1])
        for lo in range(0, total, max_pairs):
            hi = min(total, lo + max_pairs)
            pair = torch.arange(lo, hi, device=device)
            if lo == 0 and hi == total:
                owner = torch.repeat_interleave(torch.arange(n_live, device=device), counts,
                                                output_size=total)
            else:
                owner = torch.searchsorted(ends, pair, right=True)
            local = pair - starts[owner]
            width = box_cols[owner]
            dr = torch.div(local, width, rounding_mode="floor")
            dc = local - dr * width
            p = params32[owner]  # (n,12)
            dcf, drf = dc.float()[:, None], dr.float()[:, None]
            lam = p[:, 0:3] + p[:, 3:6] * dcf + p[:, 6:9] * drf
            z = p[:, 9] + p[:, 10] * dcf[:, 0] + p[:, 11] * drf[:, 0]
            inside = (lam >= 0).all(1) & (lam.sum(1) > 0) & (z >= -1) & (z <= 1)
            hit = torch.nonzero(inside).squeeze(1)
            if hit.numel() == 0:
                continue
            owner_hit = owner[hit]
            pixel = base_pixel[owner_hit] + dr[hit] * W + dc[hit]
            quantised = ((z[hit].double() + 1) * (0.5 * depth_levels)).long()
            key = (quantised << id_bits) | owner_hit
            best.scatter_reduce_(0, pixel, key, reduce="amin", include_self=True)

        covered = torch.nonzero(best != empty).squeeze(1)
        if covered.numel() == 0:
            return Raster(face_id, bary, depth)
        winner = best[covered] & ((1 << id_bits) - 1)
        # Exact barycentrics and depth of the winner only, from the float64 set-up.
        pixel_in_view = covered % (H * W)
        dr = (pixel_in_view // W - flat(row0)[winner]).double()[:, None]
        dc = (pixel_in_view % W - flat(col0)[winner]).double()[:, None]
        p = params[winner]
        lam = p[:, 0:3] + p[:, 3:6] * dc + p[:, 6:9] * dr
        z = p[:, 9] + p[:, 10] * dc[:, 0] + p[:, 11] * dr[:, 0]
        face_id.view(-1)[covered] = live[winner] % T
        bary.view(-1, 3)[covered] = (lam / lam.sum(1, keepdim=True)).float()
        depth.view(-1)[covered] = z.float()
        return Raster(face_id, bary, depth)
