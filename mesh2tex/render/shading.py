"""Image-space renders composed from a raster: masks, normals, NOC images, Lambert shading, compositing.

Every function takes and returns channels-last images (B,H,W,C), like :func:`interpolate`.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from mesh2tex.checks import check_shape, check_type
from mesh2tex.config import check_fields

from .cameras import orbit_direction
from .interpolate import check_per_view, face_attribute, interpolate
from .rasterize import Raster


def _check_mesh(function: str, vertices: torch.Tensor, tri: torch.Tensor) -> None:
    """vertices (V,3) or (B,V,3) float, tri (T,3) int."""
    check_shape(vertices, f"{function}: vertices", ("V", 3), ("B", "V", 3), dtype="float")
    check_shape(tri, f"{function}: tri", ("T", 3), dtype="int")


def render_mask(raster: Raster) -> torch.Tensor:
    """(B,H,W,1) float32 coverage: 1 where a triangle is visible, 0 on background."""
    check_type(raster, "render_mask: raster", Raster)
    return (raster.face_id >= 0).float()[..., None]


def face_normals(vertices: torch.Tensor, tri: torch.Tensor) -> torch.Tensor:
    """Unit face normals (T,3) or (B,T,3) of counter-clockwise triangles; zero for degenerate ones.

    Args:
        vertices: (V,3) or (B,V,3) float.
        tri: (T,3) int64.
    """
    _check_mesh("face_normals", vertices, tri)
    corners = vertices[..., tri, :]  # (...,T,3,3)
    normal = torch.linalg.cross(corners[..., 1, :] - corners[..., 0, :], corners[..., 2, :] - corners[..., 0, :])
    return torch.nn.functional.normalize(normal, dim=-1)


def quad_normals(vertices: torch.Tensor, quads: torch.Tensor) -> torch.Tensor:
    """Unit normals (F,3) of quads (F,4) int64 over vertices (V,3): the cross product of the diagonals,
    so both triangles of a slightly bent quad share one normal; zero for degenerate quads."""
    check_shape(vertices, "quad_normals: vertices", ("V", 3), dtype="float")
    check_shape(quads, "quad_normals: quads", ("F", 4), dtype="int")
    corners = vertices[quads]  # (F,4,3)
    normal = torch.linalg.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
    return torch.nn.functional.normalize(normal, dim=-1)


def vertex_normals(vertices: torch.Tensor, tri: torch.Tensor) -> torch.Tensor:
    """Area-weighted unit vertex normals (V,3) or (B,V,3) of vertices (V,3) or (B,V,3) float and
    triangles tri (T,3) int64; zero for unreferenced vertices."""
    _check_mesh("vertex_normals", vertices, tri)
    corners = vertices[..., tri, :]
    # length = 2 * area
    weighted = torch.linalg.cross(corners[..., 1, :] - corners[..., 0, :], corners[..., 2, :] - corners[..., 0, :])
    normals = torch.zeros_like(vertices)
    index = tri.reshape(-1).to(vertices.device)
    per_corner = weighted.unsqueeze(-2).expand(*weighted.shape[:-1], 3, 3)
    per_corner = per_corner.reshape(*weighted.shape[:-2], -1, 3)
    normals = normals.index_add(-2, index, per_corner)
    return torch.nn.functional.normalize(normals, dim=-1)


def render_normals(vertices: torch.Tensor, tri: torch.Tensor, raster: Raster, smooth: bool = True) -> torch.Tensor:
    """World-space unit normals per pixel.

    Args:
        vertices: (V,3) or (B,V,3) world-space positions (the ones that were projected).
        tri: (T,3) int64.
        raster: from :func:`rasterize`.
        smooth: interpolate area-weighted vertex normals (True) or use flat face normals (False).
    Returns:
        (B,H,W,3), unit length on covered pixels, 0 on background; differentiable w.r.t. vertices.
    """
    check_per_view(vertices, raster, "render_normals: vertices", "V", 3)
    check_shape(tri, "render_normals: tri", ("T", 3), dtype="int")
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
    check_per_view(noc, raster, "render_noc: noc", "V", 3)
    return interpolate(noc, raster, tri)


def shade_lambert(
    albedo: torch.Tensor, normals: torch.Tensor, light_dir, ambient: float = 0.3, two_sided: bool = True
) -> torch.Tensor:
    """Lambert shading ``albedo * (ambient + (1 - ambient) * max(0, n . l))``.

    Args:
        albedo: (B,H,W,C) non-negative linear colours ([0,1]; map [-1,1] network colours first).
        normals: (B,H,W,3) unit normals (from :func:`render_normals`).
        light_dir: (3,) or (B,3) direction from the surface TOWARDS the light (normalised here); a
            sequence or a tensor.
        ambient: fraction of light that reaches every surface: a float, or a (B,1,1,1) tensor (one per view).
        two_sided: light back faces as if their normal were flipped (meshes seen from inside).
    Returns:
        (B,H,W,C) shaded colours.
    """
    sizes = check_shape(albedo, "shade_lambert: albedo", ("B", "H", "W", "C"), dtype="float")
    check_shape(normals, "shade_lambert: normals", ("B", "H", "W", 3), sizes=sizes, dtype="float")
    if torch.is_tensor(ambient):
        check_shape(ambient, "shade_lambert: ambient", (), (1, 1, 1, 1), ("B", 1, 1, 1), sizes=sizes)
    light = torch.as_tensor(light_dir, dtype=normals.dtype, device=normals.device)
    check_shape(light, "shade_lambert: light_dir", (3,), (1, 3), ("B", 3), sizes=sizes)
    light = torch.nn.functional.normalize(light.reshape(-1, 3), dim=-1)[:, None, None, :]
    cosine = (normals * light).sum(-1, keepdim=True)
    cosine = cosine.abs() if two_sided else cosine.clamp(min=0)
    return albedo * (ambient + (1.0 - ambient) * cosine)


@dataclass
class LightConfig:
    """The light prior of training renders: one directional light and an ambient share per view.

    The defaults are the synthetic world's photo lights (a key light from the camera's side and
    above, never from behind the object): Lambert shading with ambient a gives each surface point
    ``albedo * (a + (1 - a) |n . l|)``.
    """

    enabled: bool = True  # shade training renders (False: the generator's colours are shown unlit, as the paper does)
    azimuth_spread: float = 70.0  # light azimuth within +- this many degrees of the camera's
    elevation_min: float = 20.0  # light elevation range, degrees above the horizon
    elevation_max: float = 75.0
    ambient_min: float = 0.35  # ambient share range
    ambient_max: float = 0.6

    def __post_init__(self):
        check_fields(
            self,
            between={
                "azimuth_spread": (0.0, 180.0),
                "elevation_min": (-90.0, 90.0),
                "elevation_max": (-90.0, 90.0),
                "ambient_min": (0.0, 1.0),
                "ambient_max": (0.0, 1.0),
            },
        )
        if self.elevation_min > self.elevation_max or self.ambient_min > self.ambient_max:
            raise ValueError("elevation_min/ambient_min must not exceed elevation_max/ambient_max")


@dataclass
class Lights:
    """One directional light per view. direction (N, 3) unit vectors towards the light, world space;
    ambient (N,) the share of light that does not depend on the normal."""

    direction: torch.Tensor
    ambient: torch.Tensor

    def to(self, device) -> "Lights":
        return Lights(self.direction.to(device), self.ambient.to(device))


def random_lights(camera_azimuth: torch.Tensor, cfg: LightConfig, generator: torch.Generator | None = None) -> Lights:
    """Lights drawn from ``cfg``'s prior for cameras at ``camera_azimuth`` (N,) degrees."""
    check_shape(camera_azimuth, "random_lights: camera_azimuth", ("N",))
    n = camera_azimuth.shape[0]
    u = torch.rand(n, 3, generator=generator)
    azimuth = camera_azimuth.float() + (u[:, 0] * 2 - 1) * cfg.azimuth_spread
    elevation = cfg.elevation_min + u[:, 1] * (cfg.elevation_max - cfg.elevation_min)
    ambient = cfg.ambient_min + u[:, 2] * (cfg.ambient_max - cfg.ambient_min)
    return Lights(orbit_direction(azimuth, elevation), ambient)


def shade_colours(
    colours: torch.Tensor, normals: torch.Tensor, direction: torch.Tensor, ambient: torch.Tensor
) -> torch.Tensor:
    """Lambert shading of network colours at P points: colours (P, 3) in [-1, 1] (albedo 0..1 mapped),
    unit normals (P, 3), light direction (P, 3), ambient (P,) -> shaded colours (P, 3) in [-1, 1].
    Two-sided, as :func:`shade_lambert` (which it applies to the albedo)."""
    sizes = check_shape(colours, "shade_colours: colours", ("P", 3), dtype="float")
    for name, value in (("normals", normals), ("direction", direction)):
        check_shape(value, f"shade_colours: {name}", ("P", 3), sizes=sizes, dtype="float")
    check_shape(ambient, "shade_colours: ambient", ("P",), sizes=sizes, dtype="float")
    albedo = (colours + 1) * 0.5
    shaded = shade_lambert(
        albedo[:, None, None], normals[:, None, None], direction, ambient.reshape(-1, 1, 1, 1).to(colours.dtype)
    )
    return shaded[:, 0, 0] * 2 - 1


def composite(rgb: torch.Tensor, mask: torch.Tensor, background) -> torch.Tensor:
    """Blend a render over a background: ``rgb * mask + background * (1 - mask)``.

    Args:
        rgb: (B,H,W,C) float.
        mask: (B,H,W,1) (or (1,H,W,1)) in [0,1], float or bool (from :func:`render_mask`, or soft).
        background: a colour (a float or a (C,) sequence or tensor), an image (H,W,C), or a batch of
            images (B,H,W,C), in the same colour range as ``rgb``.
    Returns:
        (B,H,W,C).
    """
    sizes = check_shape(rgb, "composite: rgb", ("B", "H", "W", "C"), dtype="float")
    check_shape(mask, "composite: mask", ("B", "H", "W", 1), (1, "H", "W", 1), sizes=sizes)
    background = torch.as_tensor(background, dtype=rgb.dtype, device=rgb.device)
    check_shape(
        background, "composite: background", (), (1,), ("C",), ("H", "W", "C"), ("B", "H", "W", "C"), sizes=sizes
    )
    if background.dim() <= 1:
        background = background.reshape(1, 1, 1, -1)
    elif background.dim() == 3:
        background = background[None]
    return _blend(rgb, mask.to(rgb.dtype), background)


def _broadcasts_to(shape: torch.Size, target: torch.Size) -> bool:
    try:
        return torch.broadcast_shapes(shape, target) == target
    except RuntimeError:
        return False


def _blend(images: torch.Tensor, masks: torch.Tensor, background) -> torch.Tensor:
    return images * masks + background * (1 - masks)


def composite_images(images: torch.Tensor, masks: torch.Tensor, background=1.0) -> torch.Tensor:
    """:func:`composite` for channels-first images: ``images * masks + background * (1 - masks)``.

    Args:
        images: (N,C,H,W) float, or one image (C,H,W).
        masks: (N,1,H,W) (or (1,1,H,W)) in [0,1] (soft masks blend); (1,H,W) for one image.
        background: a float, (N,C) colours (one per image), or images broadcastable to (N,C,H,W),
            in the colour range of ``images``.
    Returns:
        (N,C,H,W), or (C,H,W) for one image.
    """
    sizes = check_shape(images, "composite_images: images", ("N", "C", "H", "W"), ("C", "H", "W"), dtype="float")
    if images.dim() == 4:
        check_shape(masks, "composite_images: masks", ("N", 1, "H", "W"), (1, 1, "H", "W"), sizes=sizes)
    else:
        check_shape(masks, "composite_images: masks", (1, "H", "W"), sizes=sizes)
    if isinstance(background, torch.Tensor) and background.dim() == 2:
        check_shape(background, "composite_images: background", ("N", "C"), sizes=sizes)
        background = background[:, :, None, None]
    elif isinstance(background, torch.Tensor) and not _broadcasts_to(background.shape, images.shape):
        raise ValueError(
            f"composite_images: background must be a float, (N, C) colours or images broadcastable to "
            f"{list(images.shape)}, got {list(background.shape)}"
        )
    return _blend(images, masks, background)
