"""Attribute lookups on a raster: per-vertex interpolation, per-face lookup, texture sampling.

All three are differentiable with respect to the attributes (and the image and uv for ``texture``);
the raster itself carries no gradient, as in nvdiffrast without its antialiasing pass.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from mesh2tex.checks import check_shape, check_type

from .rasterize import Raster


def check_per_view(value: torch.Tensor, raster: Raster, name: str, *shape) -> None:
    """Check ``raster`` and a float ``value`` of ``shape`` shared by all views, or one per view ((1,)+shape or
    (B,)+shape, B the raster's batch), for the public functions that take both; ``name`` as "function: argument"."""
    check_type(raster, name.partition(":")[0] + ": raster", Raster)
    batch = {"B": (raster.face_id.shape[0], "raster")}
    check_shape(value, name, shape, (1, *shape), ("B", *shape), sizes=batch, dtype="float")


def _batched(attr: torch.Tensor, batch: int) -> torch.Tensor:
    """(N,C) or (B|1,N,C) -> (B,N,C) without copying shared attributes (shapes checked by the caller)."""
    if attr.dim() == 2:
        attr = attr[None]
    if attr.shape[0] == 1 and batch != 1:
        attr = attr.expand(batch, *attr.shape[1:])
    return attr


def _gather_rows(attr: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """attr (B,N,C), index (B,...) int64 in [0,N) -> (B,...,C)."""
    B, N, C = attr.shape
    offset = (torch.arange(B, device=index.device) * N).view(B, *([1] * (index.dim() - 1)))
    return attr.reshape(B * N, C)[(index + offset).reshape(-1)].view(*index.shape, C)


def interpolate(attr: torch.Tensor, raster: Raster, tri: torch.Tensor) -> torch.Tensor:
    """Interpolate per-vertex attributes with the raster's perspective-correct barycentrics.

    Args:
        attr: (V,C) shared by all views, or (B,V,C) (or (1,V,C)), float.
        raster: from :func:`mesh2tex.render.rasterize`, (B,H,W) face ids.
        tri: (T,3) int64, the triangles that were rasterized.
    Returns:
        (B,H,W,C) in the dtype of ``attr``, 0 on background; differentiable with respect to ``attr``.
    """
    check_per_view(attr, raster, "interpolate: attr", "V", "C")
    check_shape(tri, "interpolate: tri", ("T", 3), dtype="int")
    B = raster.face_id.shape[0]
    attr = _batched(attr, B)
    tri = tri.to(device=raster.face_id.device, dtype=torch.long)
    mask = raster.face_id >= 0
    corners = tri[raster.face_id.clamp(min=0)]  # (B,H,W,3) vertex ids
    values = _gather_rows(attr, corners)  # (B,H,W,3,C)
    weights = (raster.bary * mask[..., None]).to(attr.dtype)
    return (weights[..., None] * values).sum(-2)


def face_attribute(attr: torch.Tensor, raster: Raster) -> torch.Tensor:
    """Look up per-face attributes at every pixel.

    Args:
        attr: (T,C) shared by all views, or (B,T,C) (or (1,T,C)), float.
        raster: from :func:`mesh2tex.render.rasterize`.
    Returns:
        (B,H,W,C), 0 on background; differentiable with respect to ``attr``.
    """
    check_per_view(attr, raster, "face_attribute: attr", "T", "C")
    B = raster.face_id.shape[0]
    attr = _batched(attr, B)
    mask = raster.face_id >= 0
    values = _gather_rows(attr, raster.face_id.clamp(min=0))
    return values * mask[..., None].to(values.dtype)


def sample_texture(image: torch.Tensor, uv: torch.Tensor, mode: str = "bilinear") -> torch.Tensor:
    """Sample a texture image at UV coordinates.

    Args:
        image: (C,Ht,Wt) shared by all views, or (B,C,Ht,Wt) (or (1,C,Ht,Wt)), float.
        uv: (B,H,W,2) in [0,1]: u to the right, v UP (v = 0 is the bottom row of the image, the
            trimesh / OpenGL convention). Texel centres sit at ((k + 0.5) / Wt, 1 - (r + 0.5) / Ht).
            Coordinates outside [0,1] read the border texel.
        mode: "bilinear" or "nearest".
    Returns:
        (B,H,W,C), differentiable with respect to ``image`` and ``uv``.
    """
    sizes = check_shape(uv, "sample_texture: uv", ("B", "H", "W", 2), dtype="float")
    check_shape(
        image,
        "sample_texture: image",
        ("C", "Ht", "Wt"),
        (1, "C", "Ht", "Wt"),
        ("B", "C", "Ht", "Wt"),
        sizes=sizes,
        dtype="float",
    )
    if image.dim() == 3:
        image = image[None]
    B = uv.shape[0]
    if image.shape[0] == 1 and B != 1:
        image = image.expand(B, *image.shape[1:])
    grid = torch.stack([uv[..., 0] * 2 - 1, 1 - uv[..., 1] * 2], dim=-1).to(image.dtype)
    sampled = F.grid_sample(image, grid, mode=mode, padding_mode="border", align_corners=False)
    return sampled.permute(0, 2, 3, 1)
