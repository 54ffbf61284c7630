"""Comparing like with like: one render function for every candidate, one set of scores.

A quality table compares textured surfaces (:mod:`mesh2tex.evaluation.surfaces`) with a reference
(the photo, or the synthetic world's own render of another view). Every image of such a table comes
from :func:`render_for_comparison`: the same cameras, the same light, the same background, the same
anti-aliasing as the synthetic world's photos (``mesh2tex.synthetic.world.render_views``), so the
ground truth rendered this way reproduces the photo and wins every metric. Settings with
``lighting="albedo"`` (:class:`mesh2tex.render.RenderSettings`) render every candidate (and reference)
unlit instead.

Views are ``mesh2tex.synthetic.world.PhotoSetup`` records (camera, light, ambient, background), the ones the
world's query sidecars hold; :func:`other_views` turns the photo's view into the views it does not
show (the same camera and light turned about the vertical axis).

:func:`score_views` scores candidate renders against the reference on one object mask (pixel-aligned
geometry) or on each image's own mask (another shape): per-part CIELAB colour error, low-pass PSNR,
object-patch SWD, and masked PSNR / SSIM. :data:`METRICS` gives each metric's direction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import torch

from mesh2tex.evaluation.surfaces import Surface, SurfacePoints
from mesh2tex.metrics.appearance import lowpass_psnr, object_swd, part_colour_error
from mesh2tex.metrics.image import masked_psnr, masked_ssim
from mesh2tex.render import (
    RenderSettings,
    composite,
    face_attribute,
    face_normals,
    interpolate,
    orbit_camera,
    rasterize,
    shade_lambert,
    transform_points,
)

# name -> +1 (higher is better) or -1 (lower is better); the order of the tables' columns.
METRICS = {"part_delta_e": -1, "lowpass_psnr": 1, "swd": -1, "psnr": 1, "ssim": 1}
METRIC_TITLES = {
    "part_delta_e": "per-part ΔE",
    "lowpass_psnr": "low-pass PSNR",
    "swd": "object SWD",
    "psnr": "PSNR (mask)",
    "ssim": "SSIM (mask)",
}
ALIGNED_ONLY = ("lowpass_psnr", "psnr", "ssim")  # need pixel-aligned geometry


@dataclass
class ComparisonRender:
    """B views of one surface.

    rgb   [B, 3, R, R] float32 in [0, 1], the object over the view's background
    mask  [B, 1, R, R] float32 {0, 1}, where the object covers at least half of the pixel
    parts [B, R, R] int64, the part label seen at each object pixel's centre (-1 off the object or unknown)
    """

    rgb: torch.Tensor
    mask: torch.Tensor
    parts: torch.Tensor

    def __getitem__(self, index) -> "ComparisonRender":
        return ComparisonRender(self.rgb[index], self.mask[index], self.parts[index])


def other_views(view, azimuth_offsets=(72.0, 144.0, 216.0, 288.0)) -> list:
    """The views a photo does not show: ``view`` (a ``mesh2tex.synthetic.world.PhotoSetup``) turned about
    the vertical axis by each offset (degrees), its light turned with it (the same lighting relative
    to the camera), elevation, distance, ambient and background unchanged."""
    views = []
    for offset in azimuth_offsets:
        t = math.radians(offset)
        x, y, z = view.light
        light = (x * math.cos(t) + z * math.sin(t), y, z * math.cos(t) - x * math.sin(t))
        views.append(replace(view, azimuth=(view.azimuth + offset) % 360.0, light=tuple(round(v, 6) for v in light)))
    return views


@torch.no_grad()
def render_for_comparison(surface: Surface, views: list, settings: RenderSettings) -> ComparisonRender:
    """Render ``surface`` at ``views`` exactly as the synthetic world renders its photos.

    ``views``: ``mesh2tex.synthetic.world.PhotoSetup`` records (camera, light, ambient, background kind and
    seed). ``settings``: the world's photos' (``WorldSpec.photo_render``), with the lighting wanted. The
    mesh is rasterized at ``settings.raster_side``; each covered sub-pixel takes the surface's albedo,
    Lambert-shaded with the view's flat face normals, light and ambient (``lighting="photo"``) or left
    unlit (``"albedo"``), over the view's background (``mesh2tex.synthetic.world.random_background``);
    the result is box-filtered to ``settings.resolution``.
    """
    from mesh2tex.synthetic.world import random_background

    if not views:
        raise ValueError("render_for_comparison needs at least one view")
    big, supersample = settings.raster_side, settings.supersample
    vertices, faces = surface.vertices, surface.faces
    camera = orbit_camera(
        torch.tensor([v.azimuth for v in views], dtype=torch.float32),
        torch.tensor([v.elevation for v in views], dtype=torch.float32),
        distance=torch.tensor([v.distance for v in views], dtype=torch.float32),
        fov=torch.tensor([v.fov for v in views], dtype=torch.float32),
    )
    raster = rasterize(transform_points(vertices, camera.mvp), faces, (big, big))
    covered = raster.face_id >= 0
    points = interpolate(vertices, raster, faces)
    normals = face_attribute(face_normals(vertices, faces), raster)
    albedo = torch.zeros(covered.shape + (3,), dtype=torch.float32)
    if covered.any():
        samples = SurfacePoints(raster.face_id[covered], raster.bary[covered], points[covered], normals[covered])
        albedo[covered] = surface.colour(samples).float()
    if settings.lit:
        light = torch.tensor([v.light for v in views], dtype=torch.float32)
        ambient = torch.tensor([v.ambient for v in views], dtype=torch.float32)
        shaded = shade_lambert(albedo, normals, light, ambient[:, None, None, None])
    else:
        shaded = albedo
    background = torch.stack([torch.as_tensor(random_background(v.background, v.background_seed, big)) for v in views])
    mask = covered[..., None].float()
    rgb = composite(shaded, mask, background)
    rgb, coverage = settings.down_channels_last(rgb), settings.down_channels_last(mask)
    keep = coverage[..., 0] >= 0.5
    # Each pixel's face: its centre sub-pixel's, or where that one misses the object another covered sub-pixel's.
    centre = supersample // 2
    offsets = [(centre, centre)] + [
        (i, j) for i in range(supersample) for j in range(supersample) if (i, j) != (centre, centre)
    ]
    face = raster.face_id[:, centre::supersample, centre::supersample].clone()
    for i, j in offsets[1:]:
        face = torch.where(face >= 0, face, raster.face_id[:, i::supersample, j::supersample])
    if surface.face_parts is not None:
        parts = torch.where(face >= 0, surface.face_parts[face.clamp_min(0)], torch.full_like(face, -1))
    else:
        parts = torch.full_like(face, -1)
    parts = torch.where(keep, parts, torch.full_like(parts, -1))
    return ComparisonRender(
        rgb=rgb.permute(0, 3, 1, 2).clamp(0, 1).contiguous(), mask=keep[:, None].float(), parts=parts
    )


@dataclass
class ScoreSettings:
    lowpass_sigma: float = 3.0  # Gaussian blur of the low-pass PSNR, in pixels of the compared images
    min_part_pixels: int = 4  # a part counts in the per-part colour error once it covers this many pixels
    swd_patches: int = 256  # object patches per pyramid level and image for the SWD
    seed: int = 0  # seed of the SWD's patches and projections (the same for every candidate)


def score_views(
    candidate: ComparisonRender,
    reference_rgb: torch.Tensor,
    reference_parts: torch.Tensor,
    mask: torch.Tensor,
    settings: ScoreSettings | None = None,
    reference_mask: torch.Tensor | None = None,
) -> dict[str, list[float]]:
    """Scores of B candidate views against their references: {metric: [B] floats} (see :data:`METRICS`).

    Pixel-aligned geometry (``reference_mask`` None): every metric on the common object ``mask``
    [B, 1, R, R], the part labels ``reference_parts`` [B, R, R] for both images. Another shape
    (``reference_mask`` given): the per-part colour error between the candidate's own parts and mask
    and the reference's, the SWD between their own object patches; the aligned metrics are left out.
    ``settings``: :class:`ScoreSettings` (its defaults when None).
    """
    settings = ScoreSettings() if settings is None else settings
    rgb = candidate.rgb
    if reference_mask is None:
        scores = {
            "part_delta_e": part_colour_error(
                rgb, reference_rgb, reference_parts, mask, min_pixels=settings.min_part_pixels
            ),
            "lowpass_psnr": lowpass_psnr(rgb, reference_rgb, mask, settings.lowpass_sigma),
            "swd": object_swd(rgb, reference_rgb, mask, patches=settings.swd_patches, seed=settings.seed),
            "psnr": masked_psnr(rgb, reference_rgb, mask),
            "ssim": masked_ssim(rgb, reference_rgb, mask),
        }
    else:
        scores = {
            "part_delta_e": part_colour_error(
                rgb,
                reference_rgb,
                candidate.parts,
                mask,
                reference_parts,
                reference_mask,
                min_pixels=settings.min_part_pixels,
            ),
            "swd": object_swd(
                rgb, reference_rgb, mask, reference_mask, patches=settings.swd_patches, seed=settings.seed
            ),
        }
    return {name: [float(v) for v in values] for name, values in scores.items()}


def seen_and_unseen(scores: dict[str, list[float]]) -> dict[str, float]:
    """Per-view scores (view 0 the photo's, the rest unseen) -> {"seen <metric>": value, "unseen <metric>":
    mean over the other views}. Infinite PSNRs (identical images) stay infinite; NaNs are skipped."""
    out = {}
    for name, values in scores.items():
        out[f"seen {name}"] = values[0]
        rest = [v for v in values[1:] if not math.isnan(v)]
        if rest:
            out[f"unseen {name}"] = sum(rest) / len(rest)
    return out


def metric_direction(name: str) -> int:
    """+1 if higher is better, -1 if lower is better, 0 for values that are not scores (spreads, levels).

    Transfer columns are named '<seen|unseen> <metric>' or bare (see :data:`METRICS`); the set metrics
    of ``mesh2tex evaluate`` by their own names (kid_*, fid_*, swd, color_hist_tv, psnr_masked, ssim_masked,
    object_swd*)."""
    if name.endswith("_std") or (name.startswith("swd_") and name.endswith("px")):
        return 0
    last = name.split(" ")[-1]
    if last in METRICS:
        return METRICS[last]
    if name in ("psnr_masked", "ssim_masked"):
        return 1
    if name.startswith("object_swd"):  # the generation protocol's object SWD, against either reference
        return -1
    return -1 if name.split("_")[0] in ("kid", "fid", "swd") or name == "color_hist_tv" else 0


def common_mask(*masks: torch.Tensor) -> torch.Tensor:
    """The pixels every mask [B, 1, R, R] covers."""
    out = masks[0]
    for m in masks[1:]:
        out = out * m
    return out


def images_to_unit(images: np.ndarray) -> torch.Tensor:
    """uint8 (or [0, 1] float) images [B, H, W, 3] or [H, W, 3] -> [B, 3, H, W] float32 in [0, 1]."""
    array = np.array(images)  # a copy: the caller's array may be read-only
    tensor = torch.from_numpy(array)
    tensor = tensor.float() / 255.0 if array.dtype == np.uint8 else tensor.float()
    if tensor.dim() == 3:
        tensor = tensor[None]
    return tensor.permute(0, 3, 1, 2).contiguous()
