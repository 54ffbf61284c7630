"""The query photo, cropped around its object as every image the networks see is framed
(:mod:`mesh2tex.render.crop`), and the mesh seen at the query's pose, cropped alike."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from mesh2tex.checks import check_array_shape, check_shape, check_type
from mesh2tex.errors import InputError
from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.geometry.symmetry import mirrored_azimuth
from mesh2tex.io.images import load_image, load_mask
from mesh2tex.photos import estimate_mask, largest_region
from mesh2tex.render import (
    crop_mask,
    crop_square,
    interpolate,
    object_box,
    orbit_camera,
    rasterize,
    render_normals,
    transform_points,
)
from mesh2tex.transfer.config import TransferConfig
from mesh2tex.transfer.mask import DEFAULT_MASK_PASSES, network_probability, refine_with_grabcut


@dataclass
class Photo:
    """The query, cropped: image (1,3,R,R) in [-1,1]; mask (1,1,R,R) {0,1}."""

    image: torch.Tensor
    mask: torch.Tensor


@dataclass
class FramedView:
    """The mesh seen at the query's pose, cropped like the photo.

    mvp (1,4,4) camera; box (top, left, side) of the crop in the full render of side ``render_size``;
    noc (R,R,3) rendered NOC in [0,1]; mask (1,1,R,R); azimuth, elevation (degrees), distance and
    fov of the orbit camera, where a light placed relative to the camera starts.
    """

    mvp: torch.Tensor
    render_size: int
    box: tuple[int, int, int]
    noc: torch.Tensor
    mask: torch.Tensor
    azimuth: float = 0.0
    elevation: float = 0.0
    distance: float = 0.0  # of the orbit camera (0: not recorded)
    fov: float = 0.0


def check_photo(photo: Photo, function: str, sizes: dict | None = None) -> dict:
    """Raise unless ``photo`` is a :class:`Photo` of image (1, 3, R, R) float and mask (1, 1, R, R); the
    message names ``function``. Returns the sizes (R), for the checks of the call's other arguments."""
    check_type(photo, f"{function}: photo", Photo)
    sizes = check_shape(photo.image, f"{function}: photo.image", (1, 3, "R", "R"), sizes=sizes, dtype="float")
    return check_shape(photo.mask, f"{function}: photo.mask", (1, 1, "R", "R"), sizes=sizes)


def check_view(view: FramedView, function: str, sizes: dict | None = None) -> dict:
    """Raise unless ``view`` is a :class:`FramedView` of mvp (1, 4, 4), noc (R, R, 3) and mask (1, 1, R, R)
    float; the message names ``function``. Returns the sizes (R)."""
    check_type(view, f"{function}: view", FramedView)
    check_shape(view.mvp, f"{function}: view.mvp", (1, 4, 4), dtype="float")
    sizes = check_shape(view.noc, f"{function}: view.noc", ("R", "R", 3), sizes=sizes, dtype="float")
    return check_shape(view.mask, f"{function}: view.mask", (1, 1, "R", "R"), sizes=sizes)


def check_query(photo: Photo, view: FramedView, photo_noc: torch.Tensor | None, function: str) -> dict:
    """:func:`check_photo` and :func:`check_view` of one side R, and photo_noc (R, R, 3) float or None."""
    sizes = check_view(view, function, check_photo(photo, function))
    return check_shape(photo_noc, f"{function}: photo_noc", ("R", "R", 3), sizes=sizes, dtype="float", optional=True)


MIN_PHOTO_SIDE = 16  # the smallest query photo: fewer pixels hold no texture to transfer


def load_photo(
    image_path: str | Path, mask_path: str | Path | None, cfg: TransferConfig, mask_checkpoint: str | Path | None = None
) -> tuple[Photo, str]:
    """The query photo cropped around its object (``cfg.margin``) and resized to R = ``cfg.resolution``:
    a :class:`Photo` (image (1,3,R,R) in [-1,1], white outside the photo; mask (1,1,R,R)), and where
    the mask came from (the ``mask_path`` file, the alpha channel, or an estimate: the mask network of
    ``mask_checkpoint`` refined by GrabCut, or GrabCut alone without one). The first of
    :func:`photo_candidates`."""
    return photo_candidates(image_path, mask_path, cfg, mask_checkpoint)[0]


@dataclass
class MaskedPhoto:
    """A query photo with the masks worth trying, best guess first.

    rgb (H, W, 3) uint8, the photo as read; masks: [((H, W) bool, where it came from)]; probability
    (H, W) float32, the mask network's, when it made the estimates (else None); given: the mask came
    with the photo (a mask file or an alpha channel), so nothing is estimated or refined.
    """

    rgb: np.ndarray
    masks: list
    probability: np.ndarray | None
    given: bool


def photo_masks(
    image_path: str | Path,
    mask_path: str | Path | None,
    mask_checkpoint: str | Path | None = None,
    mask_passes: tuple[str, ...] = DEFAULT_MASK_PASSES,
) -> MaskedPhoto:
    """The photo and its masks: the ``mask_path`` file or the alpha channel when there is one; else the
    estimates, the mask network's with GrabCut edges, the network's alone and GrabCut's alone (GrabCut's
    alone without a network). The mesh picks among them (:func:`mesh2tex.transfer.pose.locate_object`):
    no estimate is right on every photo. ``mask_passes``: the network's looks at the photo
    (:func:`mesh2tex.transfer.mask.network_probability`)."""
    rgb, alpha = load_image(image_path)
    if min(rgb.shape[:2]) < MIN_PHOTO_SIDE:
        raise InputError(
            f"{image_path}: the photo is {rgb.shape[1]}x{rgb.shape[0]} pixels; a query photo needs at least "
            f"{MIN_PHOTO_SIDE}x{MIN_PHOTO_SIDE}"
        )
    probability, given = None, True  # the mask came with the photo: nothing to estimate or mend
    if mask_path is not None:
        mask = load_mask(mask_path)
        if mask.shape != rgb.shape[:2]:
            raise InputError(
                f"{mask_path}: mask is {mask.shape[1]}x{mask.shape[0]}, the photo {rgb.shape[1]}x{rgb.shape[0]}"
            )
        masks = [(mask, str(mask_path))]
    elif alpha is not None and (alpha < 128).any():
        masks = [(alpha >= 128, "alpha channel")]
    elif mask_checkpoint is not None:
        probability, given = network_probability(mask_checkpoint, rgb, passes=mask_passes), False
        masks = [
            (refine_with_grabcut(rgb, probability), "estimated (mask network, GrabCut edges)"),
            (largest_region(probability >= 0.5), "estimated (mask network)"),
            (estimate_mask(rgb), "estimated (GrabCut)"),
        ]
    else:
        masks, given = [(estimate_mask(rgb), "estimated (GrabCut)")], False
    masks = [(np.asarray(mask, dtype=bool), source) for mask, source in masks if np.asarray(mask).sum() >= 16]
    if not masks:
        raise InputError(f"{mask_path or image_path}: the object mask is empty (fewer than 16 object pixels)")
    return MaskedPhoto(rgb, masks, probability, given)


def frame_photo(rgb: np.ndarray, mask: np.ndarray, cfg: TransferConfig) -> Photo:
    """rgb (H, W, 3) uint8 and its object mask (H, W) bool -> the :class:`Photo` cropped around the object
    (``cfg.margin``) and resized to R = ``cfg.resolution``, white outside the photo."""
    check_array_shape(
        mask, "frame_photo: mask", ("H", "W"), sizes=check_array_shape(rgb, "frame_photo: rgb", ("H", "W", 3))
    )
    image = torch.from_numpy(np.array(rgb)).permute(2, 0, 1)[None].contiguous().float() / 127.5 - 1.0
    box = object_box(mask, cfg.margin)
    return Photo(image=crop_square(image, box, cfg.resolution, fill=1.0), mask=crop_mask(mask, box, cfg.resolution))


def photo_candidates(
    image_path: str | Path, mask_path: str | Path | None, cfg: TransferConfig, mask_checkpoint: str | Path | None = None
) -> list[tuple[Photo, str]]:
    """The photo framed by each of :func:`photo_masks`' masks, best guess first: [(Photo, where its mask came from)]."""
    masked = photo_masks(image_path, mask_path, mask_checkpoint)
    return [(frame_photo(masked.rgb, mask, cfg), source) for mask, source in masked.masks]


def silhouette_in_photo(
    shape: PreparedShape,
    azimuth: float,
    elevation: float,
    distance: float,
    fov: float,
    box: tuple[int, int, int],
    size: tuple[int, int],
    cfg: TransferConfig,
) -> np.ndarray:
    """(H, W) bool: where the mesh would cover the photo at the pose, framed as the photo is: the mesh's
    outline in its own square crop (:func:`view_at_pose`) laid onto the photo's crop ``box`` (top, left,
    side), the square around the photo's object mask. ``size``: the photo's (H, W)."""
    top, left, side = box
    h, w = size
    # the outline at about the photo's own scale
    sharp = dataclasses.replace(cfg, resolution=int(min(max(side, 16), 1024)))
    outline = view_at_pose(shape, azimuth, elevation, distance, fov, sharp).mask
    outline = (
        torch.nn.functional.interpolate(outline, size=(side, side), mode="bilinear", align_corners=False)[0, 0].numpy()
        >= 0.5
    )
    full = np.zeros((h, w), dtype=bool)
    r0, c0, r1, c1 = max(0, top), max(0, left), min(h, top + side), min(w, left + side)
    if r1 > r0 and c1 > c0:
        full[r0:r1, c0:c1] = outline[r0 - top : r1 - top, c0 - left : c1 - left]
    return full


def _framed_raster(
    shape: PreparedShape, azimuth: float, elevation: float, distance: float, fov: float, cfg: TransferConfig
):
    """The finest level of ``shape`` rasterized at the pose at ``cfg.render_oversample`` times R and the square
    crop around it (``cfg.margin``, as the photo's): (camera, raster, vertices (V,3), triangles (T,3), render
    side, box (top, left, side), covered (S,S) bool)."""
    size = int(round(cfg.resolution * cfg.render_oversample))
    camera = orbit_camera(torch.tensor([azimuth]), torch.tensor([elevation]), distance=distance, fov=fov)
    vertices = torch.as_tensor(shape.vertices[0], dtype=torch.float32)
    triangles = torch.as_tensor(shape.triangles(0))
    raster = rasterize(transform_points(vertices, camera.mvp), triangles, (size, size))
    covered = (raster.face_id[0] >= 0).numpy()
    if covered.sum() < 16:
        raise InputError(f"the mesh is not visible at azimuth {azimuth}, elevation {elevation} (distance {distance})")
    return camera, raster, vertices, triangles, size, object_box(covered, cfg.margin), covered


@torch.no_grad()
def view_at_pose(
    shape: PreparedShape, azimuth: float, elevation: float, distance: float, fov: float, cfg: TransferConfig
) -> FramedView:
    """Rasterize the finest level of ``shape`` at the pose (degrees; ``distance``, ``fov`` of the orbit
    camera) at ``cfg.render_oversample`` times R = ``cfg.resolution``, find the object's square crop
    (``cfg.margin``, as the photo's) and render its NOC map there: a :class:`FramedView` (noc (R,R,3), mask
    (1,1,R,R))."""
    camera, raster, vertices, triangles, size, box, covered = _framed_raster(
        shape, azimuth, elevation, distance, fov, cfg
    )
    noc = interpolate(torch.as_tensor(shape.noc, dtype=torch.float32), raster, triangles)  # (1,S,S,3)
    noc = crop_square(noc.permute(0, 3, 1, 2), box, cfg.resolution)[0].permute(1, 2, 0)
    return FramedView(
        mvp=camera.mvp,
        render_size=size,
        box=box,
        noc=noc,
        mask=crop_mask(covered, box, cfg.resolution),
        azimuth=float(azimuth),
        elevation=float(elevation),
        distance=float(distance),
        fov=float(fov),
    )


@torch.no_grad()
def normals_at_pose(
    shape: PreparedShape, azimuth: float, elevation: float, distance: float, fov: float, cfg: TransferConfig
) -> tuple[torch.Tensor, torch.Tensor]:
    """The finest level's flat face normals at the pose, framed as :func:`view_at_pose` frames its view:
    (normals (1,3,R,R), world-space unit vectors, 0 off the mesh; mask (1,1,R,R))."""
    _, raster, vertices, triangles, _, box, covered = _framed_raster(shape, azimuth, elevation, distance, fov, cfg)
    normals = render_normals(vertices, triangles, raster, smooth=False)  # (1,S,S,3)
    return crop_square(normals.permute(0, 3, 1, 2), box, cfg.resolution), crop_mask(covered, box, cfg.resolution)


def mirror_query(
    shape: PreparedShape, photo: Photo, view: FramedView, photo_noc: torch.Tensor | None, axis: int, cfg: TransferConfig
) -> tuple[Photo, FramedView, torch.Tensor | None]:
    """The query read across the mesh's mirror plane (normal to ``axis``, 0: x or 2: z, through the NOC
    frame's centre; :func:`mesh2tex.geometry.symmetry.mirror_axis`): the photo flipped left to right is
    what a camera mirrored across that plane would see of a mirror-symmetric object, so the flipped
    photo, the view at the mirrored pose and the photo's NOC flipped with its ``axis`` coordinate
    turned to 1 - c (None stays None). photo: image (1,3,R,R), mask (1,1,R,R); view with a recorded
    camera distance (:func:`view_at_pose`); photo_noc (R,R,3) or None."""
    check_query(photo, view, photo_noc, "mirror_query")
    if view.distance <= 0:
        raise ValueError("mirror_query: the view records no camera distance (build it with view_at_pose)")
    flipped = Photo(image=photo.image.flip(3), mask=photo.mask.flip(3))
    mirrored = view_at_pose(shape, mirrored_azimuth(view.azimuth, axis), view.elevation, view.distance, view.fov, cfg)
    noc = None
    if photo_noc is not None:
        noc = photo_noc.flip(1).clone()
        noc[..., axis] = 1.0 - noc[..., axis]
    return flipped, mirrored, noc
