"""The photo's light: the directional light and ambient share a transfer's renders are lit by, and where it
starts, found from the photo's shading on the mesh at the found pose."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from mesh2tex.checks import check_shape
from mesh2tex.render import LightConfig, Lights, crop_square, orbit_direction, quad_normals
from mesh2tex.transfer.config import LIGHT_STARTS
from mesh2tex.transfer.photo import FramedView, Photo, check_query


@dataclass(frozen=True)
class LightStart:
    """Where :class:`PhotoLight` starts: degrees relative to the camera (azimuth offset) and above the
    horizon, and the ambient share; ``pairs``: how many pixel pairs the search compared (0: the prior's middle)."""

    azimuth_offset: float
    elevation: float
    ambient: float
    pairs: int = 0

    @classmethod
    def prior_middle(cls, prior: LightConfig | None = None, ambient: float | None = None) -> LightStart:
        """The middle of the light prior: a key light from the camera's side and above (with ``ambient``, that
        ambient share in place of the prior's middle one)."""
        prior = prior or LightConfig()
        if ambient is None:
            ambient = 0.5 * (prior.ambient_min + prior.ambient_max)
        return cls(0.0, 0.5 * (prior.elevation_min + prior.elevation_max), ambient)


class PhotoLight(torch.nn.Module):
    """The photo's light as the renders learn it: one directional light, placed relative to the camera
    (an azimuth offset and an elevation) as the light prior places it, and an ambient share.

    It starts at ``start`` (default: the middle of :class:`mesh2tex.render.LightConfig`'s prior, a key
    light from the camera's side and above; :func:`search_light` finds a better start from the photo).
    Optimised beside the texture, it takes up the photo's shading, so the texture stays albedo: lit
    again by any light (the turntable, a GLB in Blender), it is not shaded twice.
    """

    def __init__(self, camera_azimuth: float, prior: LightConfig | None = None, start: LightStart | None = None):
        super().__init__()
        self.start = start or LightStart.prior_middle(prior)
        self.camera_azimuth = float(camera_azimuth)
        # Angles in radians (reported in degrees): with the texture's learning rates (0.01-0.05 per
        # step) a few hundred steps can turn the light anywhere, which degrees would not allow.
        self.azimuth_offset = torch.nn.Parameter(torch.tensor(math.radians(self.start.azimuth_offset)))
        self.elevation = torch.nn.Parameter(torch.tensor(math.radians(self.start.elevation)))
        self.ambient_logit = torch.nn.Parameter(torch.logit(torch.tensor(float(self.start.ambient))))

    def lights(self, mirrored_camera: float | None = None) -> Lights:
        """One light (N = 1) for :func:`mesh2tex.nn.render_texture.render_field_views`; with
        ``mirrored_camera`` (the azimuth of the camera mirrored across the mesh's mirror plane), the light
        mirrored with it: on the other side of that camera."""
        offset = torch.rad2deg(self.azimuth_offset)
        azimuth = self.camera_azimuth + offset if mirrored_camera is None else mirrored_camera - offset
        elevation = torch.rad2deg(self.elevation).clamp(-89.0, 89.0)
        direction = orbit_direction(azimuth.reshape(1), elevation.reshape(1))
        return Lights(direction, torch.sigmoid(self.ambient_logit).reshape(1))

    def describe(self) -> dict[str, float]:
        """The light found, for reports: degrees relative to the camera, the ambient share."""
        with torch.no_grad():
            return {
                "azimuth_offset": round(math.degrees(self.azimuth_offset.item()), 2),
                "elevation": round(math.degrees(self.elevation.item()), 2),
                "ambient": round(torch.sigmoid(self.ambient_logit).item(), 4),
            }


# Pixel pairs this far apart (crop pixels, right and down) are compared; a normal that changes between them
# is a fold of the surface, where the shading changes and, on one material, the albedo does not.
_PAIR_OFFSETS = (2, 4)
_MIN_FOLD = 0.2  # |n_p - n_q| above this: the pair straddles a fold
_MIN_PAIRS = 32  # fewer fold pairs than this: the photo says too little about its light; keep the prior's middle


def fold_pairs(photo: Photo, view: FramedView, batch, samples) -> tuple[torch.Tensor, torch.Tensor]:
    """The pixel pairs of the photo's crop that straddle a fold of the surface, both on the photo's mask and
    the mesh, each pixel on one flat piece: their log luminance differences (P,) and their normals (P, 2, 3).
    ``samples``: the mesh rasterized at ``view`` (its full render, ``view.render_size``)."""
    check_query(photo, view, None, "fold_pairs")
    check_shape(samples.triangle_id, "fold_pairs: samples.triangle_id", (1, view.render_size, view.render_size))
    size = photo.image.shape[-1]
    ids = samples.triangle_id[:1]  # (1, S, S)
    covered = ids >= 0
    normals = quad_normals(batch.vertices, batch.quads)[ids.clamp(min=0) // 2] * covered[..., None]  # (1, S, S, 3)
    # Cropped as the photo was: resampling blends the normals of neighbouring pieces (and the photo's pixels
    # there); a pixel lies on one piece where the blend is still a unit vector.
    normals = crop_square(normals.permute(0, 3, 1, 2).float(), view.box, size)[0]  # (3, R, R)
    pure = (normals.norm(dim=0) > 0.995) & (photo.mask[0, 0] > 0.5) & (view.mask[0, 0] > 0.5)
    luminance = ((photo.image[0] + 1) * 0.5).mean(0).clamp(min=0.02).log()  # (R, R)
    diffs, pairs = [], []
    for step in _PAIR_OFFSETS:
        for dy, dx in ((0, step), (step, 0)):
            a = (slice(0, size - dy), slice(0, size - dx))
            b = (slice(dy, size), slice(dx, size))
            na, nb = normals[:, a[0], a[1]], normals[:, b[0], b[1]]
            fold = pure[a] & pure[b] & ((na - nb).norm(dim=0) > _MIN_FOLD)
            diffs.append((luminance[a] - luminance[b])[fold])
            pairs.append(torch.stack([na[:, fold].t(), nb[:, fold].t()], 1))
    return torch.cat(diffs), torch.cat(pairs)


def search_light(
    photo: Photo,
    view: FramedView,
    batch,
    samples,
    prior: LightConfig | None = None,
    step: float = 5.0,
    ambient: float | None = None,
) -> LightStart:
    """The light of the prior's range that explains the photo's shading best, if the mesh at the found pose
    shows enough folds (else the prior's middle); with ``ambient``, only its direction is searched and the
    ambient share is held there.

    Lambert shading with ambient a multiplies the albedo by s = a + (1 - a)|n . l|; across a fold of one
    material the albedo stays and the log luminance changes by log s_p - log s_q. Every light of the prior
    (azimuth offsets, elevations ``step`` degrees apart, ambient shares 0.05 apart) is scored by the median
    absolute difference between that change and the photo's over the fold pairs (:func:`fold_pairs`): the
    median, because pairs across two materials are far off for every light and must not decide.
    photo: image (1, 3, R, R), mask (1, 1, R, R); view: the mesh at the found pose, its crop.
    """
    prior = prior or LightConfig()
    with torch.no_grad():
        observed, normals = fold_pairs(photo, view, batch, samples)
        if observed.numel() < _MIN_PAIRS:
            return LightStart.prior_middle(prior, ambient)
        offsets = torch.arange(-prior.azimuth_spread, prior.azimuth_spread + 1e-6, step)
        elevations = torch.arange(prior.elevation_min, prior.elevation_max + 1e-6, step)
        if ambient is None:
            ambients = torch.arange(prior.ambient_min, prior.ambient_max + 1e-6, 0.05)
        else:
            ambients = torch.tensor([float(ambient)])
        grid_az, grid_el = torch.meshgrid(offsets, elevations, indexing="ij")
        directions = orbit_direction(view.azimuth + grid_az.flatten(), grid_el.flatten())  # (L, 3)
        cosines = (normals.float() @ directions.t()).abs()  # (P, 2, L)
        shading = ambients[:, None, None, None] + (1 - ambients[:, None, None, None]) * cosines  # (A, P, 2, L)
        predicted = shading[:, :, 0].log() - shading[:, :, 1].log()  # (A, P, L)
        error = (predicted - observed[None, :, None]).abs().median(1).values  # (A, L)
        best = int(error.argmin())
        a, light = divmod(best, directions.shape[0])
    return LightStart(
        round(float(grid_az.flatten()[light]), 2),
        round(float(grid_el.flatten()[light]), 2),
        round(float(ambients[a]), 2),
        int(observed.numel()),
    )


def starting_light(
    photo: Photo, view: FramedView, batch, samples, start: str | LightStart, ambient: float | None = None
) -> PhotoLight:
    """The photo's light for a transfer at ``view``, on the device of ``samples`` (the mesh rasterized at ``view``),
    started at ``start``: a :class:`LightStart`, or as ``TransferConfig.light_start`` says ('prior', the prior's
    middle; 'search', :func:`search_light`), with its ambient share at ``ambient`` when given (a named start only:
    a LightStart is used as it is). photo: image (1, 3, R, R), mask (1, 1, R, R)."""
    if isinstance(start, str):
        if start not in LIGHT_STARTS:
            raise ValueError(f"starting_light: start {start!r}: a LightStart or one of {', '.join(LIGHT_STARTS)}")
        if start == "search":
            start = search_light(photo, view, batch, samples, ambient=ambient)
        else:
            start = LightStart.prior_middle(ambient=ambient)
    return PhotoLight(view.azimuth, start=start).to(samples.triangle_id.device)


__all__ = ["LightStart", "PhotoLight", "fold_pairs", "search_light", "starting_light"]
