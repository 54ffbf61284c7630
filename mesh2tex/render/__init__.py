"""Rendering in PyTorch (the rasterizer's CPU loop compiled by numba): orbit cameras, a rasterizer,
interpolation, shading, UV-space baking.

Four primitives in the spirit of nvdiffrast, composed by the caller::

    cam = orbit_camera(azimuth, elevation)              # view / proj / mvp (B,4,4)
    pos = transform_points(vertices, cam.mvp)           # (B,V,4) clip space
    raster = rasterize(pos, faces, (H, W))              # face_id, bary, depth
    colour = interpolate(vertex_colours, raster, faces) # (B,H,W,C), differentiable

Conventions (OpenGL clip space, pixel centres, camera, uv orientation) are in docs/rendering.md.
"""

from .cameras import (
    Camera,
    CameraConfig,
    orbit_camera,
    orbit_direction,
    perspective,
    transform_points,
    turntable_angles,
)
from .crop import crop_mask, crop_square, object_box
from .interpolate import face_attribute, interpolate, sample_texture
from .rasterize import Raster, pixel_centres, rasterize
from .settings import RenderSettings
from .shading import (
    LightConfig,
    Lights,
    composite,
    composite_images,
    face_normals,
    quad_normals,
    random_lights,
    render_mask,
    render_noc,
    render_normals,
    shade_colours,
    shade_lambert,
    vertex_normals,
)
from .uv import dilate_texture, unwrap_uv, uv_rasterize

__all__ = [
    "Camera",
    "CameraConfig",
    "LightConfig",
    "Lights",
    "Raster",
    "RenderSettings",
    "composite",
    "composite_images",
    "crop_mask",
    "crop_square",
    "dilate_texture",
    "face_attribute",
    "face_normals",
    "interpolate",
    "object_box",
    "orbit_camera",
    "orbit_direction",
    "perspective",
    "pixel_centres",
    "rasterize",
    "render_mask",
    "render_noc",
    "quad_normals",
    "random_lights",
    "render_normals",
    "shade_colours",
    "shade_lambert",
    "sample_texture",
    "transform_points",
    "turntable_angles",
    "unwrap_uv",
    "uv_rasterize",
    "vertex_normals",
]
