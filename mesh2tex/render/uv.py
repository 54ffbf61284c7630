"""UV space: the mesh drawn at its texture coordinates (for baking), seam padding, UV unwrapping."""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from mesh2tex.checks import check_shape
from mesh2tex.io.images import images_to_uint8

from .rasterize import Raster, rasterize
from .surface_texture import read_colours


def uv_rasterize(uv: torch.Tensor, tri: torch.Tensor, resolution) -> Raster:
    """Rasterize a mesh at its UV coordinates: texel (row r, column k) of an (H,W) texture image.

    Args:
        uv: (V,2) float in [0,1], tensor or array; u to the right, v UP (v = 0 is the bottom row of the image, the
            convention of :func:`mesh2tex.render.texture`), so the texel centre of row r, column k is
            at u = (k + 0.5) / W, v = 1 - (r + 0.5) / H.
        tri: (T,3) int64 triangles indexing ``uv``, tensor or array.
        resolution: (H, W) of the texture image.
    Returns:
        Raster of batch 1: for every texel the triangle under its centre and the barycentrics there,
        so ``interpolate(vertex_positions, raster, tri)`` gives the surface point of each texel.
    """
    uv, tri = torch.as_tensor(uv), torch.as_tensor(tri)
    check_shape(uv, "uv_rasterize: uv", ("V", 2), dtype="float")
    check_shape(tri, "uv_rasterize: tri", ("T", 3), dtype="int")
    pos = torch.cat([uv * 2 - 1, torch.zeros_like(uv[:, :1]), torch.ones_like(uv[:, :1])], dim=1)
    return rasterize(pos[None], tri, resolution)


# --uv auto keeps a mesh's own UVs unless more than this share of their area lies on texels that
# another triangle covers too (mirrored or stacked charts: one texel for two places on the surface).
UV_OVERLAP_LIMIT = 0.02
UV_RANGE_TOLERANCE = 1e-3  # how far outside [0, 1] a UV may stray (rounding in exporters)


def uv_atlas_problem(uv, faces, resolution: int = 1024) -> str:
    """'' when ``uv`` is a usable atlas for baking a texture, else why not, in a few words.

    Usable: finite, inside [0, 1] (wrapped or tiled UVs would repeat texels over the surface), of
    non-zero area, and with charts that do not overlap: the triangles' UV area, summed, may exceed the
    area they cover together (counted on a ``resolution``-square grid of texel centres) by at most
    :data:`UV_OVERLAP_LIMIT` of it.

    Args:
        uv: (V, 2) float, v up; faces: (T, 3) int indexing ``uv`` (arrays or tensors).
    """
    uv = torch.as_tensor(uv).double()
    faces = torch.as_tensor(faces).long()
    check_shape(uv, "uv_atlas_problem: uv", ("V", 2), dtype="float")
    check_shape(faces, "uv_atlas_problem: faces", ("T", 3), dtype="int")
    if not bool(torch.isfinite(uv).all()):
        return "its UV coordinates are not all finite"
    corners = uv[faces]  # (T, 3, 2)
    low, high = float(corners.min()), float(corners.max())
    if low < -UV_RANGE_TOLERANCE or high > 1 + UV_RANGE_TOLERANCE:
        return f"its UVs leave [0, 1] (from {low:.2f} to {high:.2f}: a tiled or wrapped texture)"
    edge1, edge2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    area = float((edge1[:, 0] * edge2[:, 1] - edge1[:, 1] * edge2[:, 0]).abs().sum() / 2)
    if area * resolution * resolution < 1:
        return "its UV triangles have no area"
    covered = int((uv_rasterize(uv.float(), faces, (resolution, resolution)).face_id[0] >= 0).sum())
    overlap = 1 - covered / (area * resolution * resolution)
    if overlap > UV_OVERLAP_LIMIT:
        return f"its UV charts overlap ({100 * overlap:.0f} % of their area shares texels: mirrored or stacked parts)"
    return ""


def dilate_texture(image: torch.Tensor, mask: torch.Tensor, pixels: int) -> torch.Tensor:
    """Pad a texture's charts outwards so that bilinear lookups near seams do not read background.

    Each step gives every empty texel next to a filled one the mean of its filled 3x3 neighbours.

    Args:
        image: (C,H,W) or (B,C,H,W) float texture.
        mask: (H,W), (B,H,W) or (B,1,H,W) (B = 1 for a (C,H,W) image), bool or float, True/1 where the
            texture is defined.
        pixels: number of texels to grow by.
    Returns:
        Tensor shaped like ``image``: defined texels unchanged, up to ``pixels`` texels around them
        filled, the rest as in ``image``.
    """
    sizes = check_shape(image, "dilate_texture: image", ("C", "H", "W"), ("B", "C", "H", "W"), dtype="float")
    sizes.setdefault("B", (1, "image"))
    check_shape(mask, "dilate_texture: mask", ("H", "W"), ("B", "H", "W"), ("B", 1, "H", "W"), sizes=sizes)
    squeeze = image.dim() == 3
    images = image[None] if squeeze else image
    filled = mask.to(images.dtype).reshape(-1, 1, *images.shape[-2:])
    result = images * filled
    kernel = torch.ones(1, 1, 3, 3, dtype=images.dtype, device=images.device)
    channels = images.shape[1]
    for _ in range(int(pixels)):
        weight = F.conv2d(filled, kernel, padding=1)
        total = F.conv2d(result.reshape(-1, 1, *result.shape[-2:]), kernel, padding=1)
        total = total.reshape(result.shape)
        grow = (filled == 0) & (weight > 0)
        if not bool(grow.any()):
            break
        mean = total / weight.clamp(min=1)
        result = torch.where(grow, mean, result)
        filled = torch.where(grow, torch.ones_like(filled), filled)
    result = torch.where(filled.expand(-1, channels, -1, -1) > 0, result, images)
    return result[0] if squeeze else result


def unwrap_uv(vertices, faces):
    """Compute a UV atlas with xatlas; vertices on chart seams are split.

    Args:
        vertices: (V,3) float array or tensor.
        faces: (T,3) int array or tensor.
    Returns:
        (new_vertices (V',3) float32, new_faces (T,3) int64, uv (V',2) float32 in [0,1] with v up,
        vertex_map (V',) int64 index of each new vertex in ``vertices``), as torch tensors when
        ``vertices`` is a tensor, else as numpy arrays.
    """
    import xatlas

    as_torch = torch.is_tensor(vertices)
    v = vertices.detach().cpu().numpy() if as_torch else np.asarray(vertices)
    f = faces.detach().cpu().numpy() if torch.is_tensor(faces) else np.asarray(faces)
    vertex_map, new_faces, uv = xatlas.parametrize(v.astype(np.float32), f.astype(np.uint32))
    result = (
        v[vertex_map].astype(np.float32),
        new_faces.astype(np.int64),
        uv.astype(np.float32),
        vertex_map.astype(np.int64),
    )
    if as_torch:
        return tuple(torch.from_numpy(a).to(vertices.device) for a in result)
    return result


def bake_surface_colours(
    vertices: torch.Tensor, triangles: torch.Tensor, texture, size: int, dilate: int = 8, device=None
):
    """Bake a texture bound to a mesh into a UV image over a fresh atlas.

    Args:
        vertices: (V,3) float, triangles: (T,3) int64 of the mesh (tensors).
        texture: a :class:`~mesh2tex.render.surface_texture.SurfaceTexture` bound to ``triangles``
            (``texture.colours(triangle_id (P,), bary (P,3))`` in its corner order, RGB in [-1, 1]),
            read on ``device`` (default: the vertices').
        size: texture side in texels; dilate: texels of padding around each chart.
    Returns:
        (vertices (V',3) float32, faces (T,3) int64, uv (V',2) float32, texture (size,size,3) uint8,
        coverage (size,size) bool), CPU tensors/arrays; faces keep the order and corners of
        ``triangles`` (vertices are split on seams), so texel colours equal the texture's exactly.
    """
    check_shape(vertices, "bake_surface_colours: vertices", ("V", 3), dtype="float")
    check_shape(triangles, "bake_surface_colours: triangles", ("T", 3), dtype="int")
    device = vertices.device if device is None else device
    triangles = triangles.cpu()
    new_vertices, faces, uv, vertex_map = unwrap_uv(vertices.cpu(), triangles)
    if not torch.equal(vertex_map[faces], triangles):
        raise RuntimeError("unwrap_uv changed the face order or corners; baking needs them kept")
    raster = uv_rasterize(uv, faces, (size, size))
    covered = raster.face_id[0] >= 0
    colours = torch.zeros(size, size, 3)
    colours[covered] = read_colours(texture, raster.face_id[0][covered], raster.bary[0][covered], device)
    image = dilate_texture(colours.permute(2, 0, 1), covered[None].float(), dilate).reshape(3, size, size)
    return new_vertices.float(), faces, uv.float(), images_to_uint8(image), covered
