"""Image-space renders composed from a raster: masks, normals, NOC images, Lambert shading, compositing.

Every function takes and returns channels-last images (B,H,W,C), like :func:`interpolate`.
"""

from __future__ import annotations

import torch

from .interpolate import face_attribute, interpolate
from .rasterize import Raster


def render_mask(raster: Raster) -> torch.Tensor:
    """(B,H,W,1) float32 coverage: 1 where a triangle is visible, 0 on background."""
    return (raster.face_id >= 0).float()[..., None]


def face_normals(vertices: torch.Tensor, tri: torch.Tensor) -> torch.Tensor:
    """Unit face normals (T,3) or (B,T,3) of counter-clockwise triangles; zero for degenerate ones.

    Args:
        vertices: (V,3) or (B,V,3) float.
        tri: (T,3) int64.
    """
    corners = vertices[..., tri, :]  # (...,T,3,3)
    normal = torch.linalg.cross(corners[..., 1, :] - corners[..., 0, :],
                                corners[..., 2, :] - corners[..., 0, :])
    return torch.nn.functional.normalize(normal, dim=-1)


def vertex_normals(vertices: torch.Tensor, tri: torch.Tensor) -> torch.Tensor:
    """Area-weighted unit vertex normals (V,3) or (B,V,3); zero for unreferenced vertices."""
    corners = vertices[..., tri, :]
    weighted = torch.linalg.cross(corners[..., 1, :] - corners[..., 0, :],
                                  corners[..., 2, :] - corners[..., 0, :])  # length = 2 * area
    normals = torch.zeros_like(vertices)
    index = tri.reshape(-1).to(vertices.device)
    per_corner = weighted.unsqueeze(-2).expand(*weighted.shape[:-1], 3, 3)
    per_corner = per_corner.reshape(*weighted.shape[:-2], -1, 3)
    normals = normals.index_add(-2, index, per_corner)
    return torch.nn.functional.normalize(normals, dim=-1)


def render_normals(vertices: torch.Tensor, tri: torch.Tensor, raster: Raster,
                   smooth: bool = True) -> torch.Tensor:
    """World-space unit normals per pixel.

    Args:
        vertices: (V,3) or (B,V,3) world-space positions (the ones that were projected).
        tri: (T,3) int64.
        raster: from :func:`rasterize`.
        smooth: interpolate area-weighted vertex normals (True) or use flat face normals (False).
    Returns:
        (B,H,W,3), unit length on covered pixels, 0 on background; differentiable w.r.t. vertices.
    """
    if smooth:
        normals = interpolate(vertex_normals(vertices, tri), raster, tri)
        return torch.nn.functional.normalize(normals, dim=-1)
    return face_attribute(face_normals(vertices, tri), raster)


def render_noc(noc: torch.Tensor, raster: Raster, tri: torch.Tensor) -> torch.Tensor:
    """Normalised object coordinates per pixel.

    Args:
        noc: (V,3) or (B,V,3) per-vertex NOC in [0,1] (e.g. ``PreparedShape.noc``, or
            ``mesh2tex.geometry.features.noc_coordinates`` of the vertices).
        raster, tri: as for :func:`interpolate`.
    Returns:
        (B,H,W,3) in [0,1], 0 on background (use :func:`render_mask` to tell background apart).
    """
    return interpolate(noc, raster, tri)


def shade_lambert(albedo: torch.Tensor, normals: torch.Tensor, light_dir, ambient: float = 0.3,
                  two_sided: bool = True) -> torch.Tensor:
    """Lambert shading ``albedo * (ambient + (1 - ambient) * max(0, n . l))``.

    Args:
        albedo: (B,H,W,C) non-negative linear colours ([0,1]; map [-1,1] network colours first).
        normals: (B,H,W,3) unit normals (from :func:`render_normals`).
        light_dir: (3,) or (B,3) direction from the surface TOWARDS the light (normalised here).
        ambient: fraction of light that reaches every surface.
        two_sided: light back faces as if their normal were flipped (meshes seen from inside).
    Returns:
        (B,H,W,C) shaded colours.
    """
    light = torch.as_tensor(light_dir, dtype=normals.dtype, device=normals.device)
    light = torch.nn.functional.normalize(light.reshape(-1, 3), dim=-1)[:, None, None, :]
    cosine = (normals * light).sum(-1, keepdim=True)
    cosine = cosine.abs() if two_sided else cosine.clamp(min=0)
    return albedo * (ambient + (1.0 - ambient) * cosine)


def composite(rgb: torch.Tensor, mask: torch.Tensor, background) -> torch.Tensor:
    """Blend a render over a background: ``rgb * mask + background * (1 - mask)``.

    Args:
        rgb: (B,H,W,C).
        mask: (B,H,W,1) in [0,1] (from :func:`render_mask`, or soft).
        background: a colour (a float or a (C,) sequence or tensor), an image (H,W,C), or a batch of
            images (B,H,W,C), in the same colour range as ``rgb``.
    Returns:
        (B,H,W,C).
    """
    background = torch.as_tensor(background, dtype=rgb.dtype, device=rgb.device)
    if background.dim() <= 1:
        background = background.reshape(1, 1, 1, -1)
    elif background.dim() == 3:
        background = background[None]
    return composite_images(rgb, mask.to(rgb.dtype), background)


def composite_images(images: torch.Tensor, masks: torch.Tensor, background=1.0) -> torch.Tensor:
    """:func:`composite` for channels-first images: ``images * masks + background * (1 - masks)``.

    Args:
        images: (N,C,H,W).
        masks: (N,1,H,W) in [0,1] (soft masks blend).
        background: a float, (N,C) colours (one per image), or images broadcastable to (N,C,H,W),
            in the colour range of ``images``.
    Returns:
        (N,C,H,W).
    """
    if isinstance(background, torch.Tensor) and background.dim() == 2:
        background = background[:, :, None, None]
    return images * masks + background * (1 - masks)
