"""The query's pose: the pose network's beliefs over its bins, refined by a silhouette search;
and the photo's NOC map by the NOC network."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from mesh2tex.checks import check_shape, check_type
from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.models import load_view_network
from mesh2tex.nn.pose import PoseBins
from mesh2tex.render import crop_mask, object_box, orbit_camera, rasterize, transform_points
from mesh2tex.transfer.config import TransferConfig
from mesh2tex.transfer.mask import refine_with_outline
from mesh2tex.transfer.photo import (
    MaskedPhoto,
    Photo,
    check_photo,
    frame_photo,
    normals_at_pose,
    silhouette_in_photo,
)


@torch.no_grad()
def predict_pose(checkpoint: str | Path, photo: Photo, device: torch.device) -> tuple[float, float]:
    """Azimuth and elevation (degrees, bin centres) of the photo (image (1, 3, R, R), mask (1, 1, R, R)) by the
    pose network."""
    check_photo(photo, "predict_pose")
    return pose_network_beliefs(checkpoint, photo, device).most_likely()


@dataclass
class PoseBeliefs:
    """The pose network's softmax over its bins for one photo: azimuth [A], elevation [E] float32 (CPU)."""

    bins: PoseBins
    azimuth: torch.Tensor
    elevation: torch.Tensor

    def most_likely(self) -> tuple[float, float]:
        """Centres (degrees) of the most likely azimuth and elevation bins."""
        return (
            float(self.bins.bin_to_azimuth(int(self.azimuth.argmax()))),
            float(self.bins.bin_to_elevation(int(self.elevation.argmax()))),
        )


@torch.no_grad()
def pose_network_beliefs(checkpoint: str | Path, photo: Photo, device: torch.device) -> PoseBeliefs:
    """The pose network's bin probabilities for the photo (image (1, 3, R, R), mask (1, 1, R, R))."""
    check_photo(photo, "pose_network_beliefs")
    net, cfg = load_view_network(checkpoint, "pose", device)
    azimuth_logits, elevation_logits = net(_network_input(photo, cfg.data.resolution, device))
    return PoseBeliefs(
        net.bins, F.softmax(azimuth_logits, 1)[0].float().cpu(), F.softmax(elevation_logits, 1)[0].float().cpu()
    )


@torch.no_grad()
def silhouette_iou(
    shape: PreparedShape,
    photo_mask: torch.Tensor,
    azimuths: torch.Tensor,
    elevations: torch.Tensor,
    distance: float,
    fov: float,
    margin: float,
    size: int = 64,
    batch: int = 24,
) -> torch.Tensor:
    """IoU of the photo's object mask with the mesh's silhouette at each pose, both cropped alike.

    photo_mask (1,1,R,R) {0,1}, already cropped around the object with ``margin``; azimuths,
    elevations [N] degrees. Each silhouette is rasterized, cropped around itself with the same
    margin (so the camera distance does not matter) and compared at ``size`` x ``size``. Returns [N].
    """
    check_shape(photo_mask, "silhouette_iou: photo_mask", (1, 1, "R", "R"))
    sizes = check_shape(azimuths, "silhouette_iou: azimuths", ("N",))
    check_shape(elevations, "silhouette_iou: elevations", ("N",), sizes=sizes)
    target = F.interpolate(photo_mask.float().cpu(), size=(size, size), mode="area")[0, 0] > 0.5
    vertices = torch.as_tensor(shape.vertices[0], dtype=torch.float32)
    triangles = torch.as_tensor(shape.triangles(0))
    render = int(round(size * 1.5))
    scores = []
    for start in range(0, azimuths.shape[0], batch):
        camera = orbit_camera(
            azimuths[start : start + batch].float(),
            elevations[start : start + batch].float(),
            distance=distance,
            fov=fov,
        )
        covered = (rasterize(transform_points(vertices, camera.mvp), triangles, (render, render)).face_id >= 0).numpy()
        for view in covered:
            if view.sum() < 4:
                scores.append(0.0)
                continue
            crop = crop_mask(view, object_box(view, margin), size)[0, 0] > 0.5
            scores.append(float((crop & target).sum()) / max(float((crop | target).sum()), 1.0))
    return torch.tensor(scores)


@dataclass
class PoseEstimate:
    """Where the camera is (degrees) and how it was found; ``network``: the pose network's own bin centres."""

    azimuth: float
    elevation: float
    source: str
    network: tuple[float, float] | None = None
    silhouette_iou: float | None = None  # of the chosen pose
    network_silhouette_iou: float | None = None  # of the network's own pose
    # where the half turn was weighed (:func:`search_pose`): the crease agreement at the pose the silhouettes
    # found and at its half turn, and whether the half turn won
    creases: tuple[float, float] | None = None
    turned: bool = False


# crease_agreement compares at most this many pixels a side: a crease a pixel wide at 128 px moves off its
# match with a few degrees of pose, and the search's grid is 5 degrees (docs/results/transfer.md)
CREASE_SIDE = 64


def crease_agreement(photo: Photo, normals: torch.Tensor, mask: torch.Tensor) -> float:
    """How well the creases the mesh's faces draw at a pose line up with the photo's edges: the correlation
    of the photo's grey gradient magnitude with the face-normal map's, on the pixels both cover (each mask
    eroded by two pixels, so the outline, which a pose and its half turn nearly share, does not count), at
    :data:`CREASE_SIDE` pixels a side at most.

    photo: image (1, 3, R, R), mask (1, 1, R, R); normals (1, 3, R, R) and mask (1, 1, R, R) of the mesh framed
    alike (:func:`mesh2tex.transfer.photo.normals_at_pose`). Shading changes where faces turn, whatever the
    light and the paint, so a car's windscreen, bonnet and boot draw edges that its outline does not show: on
    32 shaded photos of four cars made apart from the world the true pose scored above its half turn on 31
    (``benchmarks/crease_halfturn.py``, docs/results/transfer.md). Returns a value in [-1, 1] (0 when nothing
    is left to compare)."""
    sizes = check_photo(photo, "crease_agreement")
    check_shape(normals, "crease_agreement: normals", (1, 3, "R", "R"), sizes=sizes, dtype="float")
    check_shape(mask, "crease_agreement: mask", (1, 1, "R", "R"), sizes=sizes)
    from kornia.filters import sobel

    side = min(int(photo.image.shape[-1]), CREASE_SIDE)
    grey, normals = (F.interpolate(x.float(), size=(side, side), mode="area") for x in (photo.image, normals))
    both = F.interpolate(photo.mask.float() * mask.float(), size=(side, side), mode="area") > 0.5
    photo_edges, mesh_edges = sobel(grey.mean(1, keepdim=True))[0, 0], sobel(normals).sum(1)[0]
    inner = -F.max_pool2d(-both.float(), 5, stride=1, padding=2)[0, 0] > 0.5
    if int(inner.sum()) < 16:
        return 0.0
    a, b = photo_edges[inner], mesh_edges[inner]
    a, b = a - a.mean(), b - b.mean()
    scale = float(a.norm() * b.norm())
    return float((a * b).sum()) / scale if scale > 0 else 0.0


def creases_near(
    shape: PreparedShape,
    photo: Photo,
    azimuth: float,
    elevation: float,
    spread: float,
    distance: float,
    fov: float,
    cfg: TransferConfig,
) -> float:
    """The best :func:`crease_agreement` of the photo (image (1, 3, R, R), mask (1, 1, R, R)) with the mesh at
    the pose and at the 8 poses ``spread`` degrees from it in azimuth, elevation or both: creases are thin, and
    a pose the search found is a few degrees off."""
    return max(
        crease_agreement(photo, *normals_at_pose(shape, (azimuth + d_az) % 360.0, elevation + d_el, distance, fov, cfg))
        for d_az in (-spread, 0.0, spread)
        for d_el in (-spread, 0.0, spread)
    )


def search_pose(
    shape: PreparedShape, photo: Photo, beliefs: PoseBeliefs, distance: float, fov: float, cfg: TransferConfig
) -> PoseEstimate:
    """The pose whose silhouette best matches the photo's mask (render and compare).

    The pose network proposes the elevations (the centres of its ``pose_search_elevations`` most
    likely bins); every azimuth ``pose_search_step`` degrees apart is tried with each, then the
    best one's neighbours at half the step in both angles. Silhouettes tell a chair's front from its
    back where the network, trained on few shapes, often does not (docs/style_and_pose.md has figures);
    where they barely do (a car seen from the front or the back), the network's most likely azimuth
    bin is kept: its best pose wins if its IoU is within ``pose_search_tie`` of the best anywhere. Then the
    pose's half turn (searched alike about it) wins where its IoU is within ``pose_halfturn_tie`` of the found
    one's and the mesh's creases there agree better with the photo's edges (:func:`creases_near`, half a
    step about each: the fine pass's grid).
    photo: image (1, 3, R, R), mask (1, 1, R, R).
    """
    check_photo(photo, "search_pose")
    check_type(beliefs, "search_pose: beliefs", PoseBeliefs)
    check_shape(beliefs.azimuth, "search_pose: beliefs.azimuth", ("A",), dtype="float")
    check_shape(beliefs.elevation, "search_pose: beliefs.elevation", ("E",), dtype="float")
    bins, step = beliefs.bins, float(cfg.pose_search_step)

    def best_of(azimuths: torch.Tensor, elevations: torch.Tensor, keep_bin: bool = False) -> tuple[float, float, float]:
        iou = silhouette_iou(shape, photo.mask, azimuths, elevations, distance, fov, cfg.margin)
        azimuth_bins = bins.azimuth_to_bin(azimuths)
        prior = beliefs.azimuth[azimuth_bins] * beliefs.elevation[bins.elevation_to_bin(elevations)]
        score = iou + 1e-6 * prior  # the prior only breaks exact ties
        best = int(torch.argmax(score))
        in_bin = azimuth_bins == int(beliefs.azimuth.argmax())
        if keep_bin and in_bin.any():
            local = int(torch.argmax(torch.where(in_bin, score, torch.tensor(-1.0))))
            if iou[local] >= iou[best] - cfg.pose_search_tie:
                best = local
        return float(azimuths[best]), float(elevations[best]), float(iou[best])

    order = beliefs.elevation.argsort(descending=True)[: max(1, cfg.pose_search_elevations)]
    elevations = bins.bin_to_elevation(order).float()
    azimuths = torch.arange(0.0, 360.0, step)
    best_az, best_el, _ = best_of(
        azimuths.repeat(len(elevations)), elevations.repeat_interleave(len(azimuths)), keep_bin=True
    )
    offsets = torch.tensor([-0.5, 0.0, 0.5]) * step
    best_az, best_el, best_iou = best_of(
        (best_az + offsets).repeat(3) % 360.0, (best_el + offsets).repeat_interleave(3)
    )
    creases, turned = None, False
    if cfg.pose_halfturn_tie >= 0:
        turn_az, turn_el, turn_iou = best_of(
            (best_az + 180.0 + offsets).repeat(3) % 360.0, (best_el + offsets).repeat_interleave(3)
        )
        if turn_iou >= best_iou - cfg.pose_halfturn_tie:
            creases = tuple(
                round(creases_near(shape, photo, az, el, 0.5 * step, distance, fov, cfg), 4)
                for az, el in ((best_az, best_el), (turn_az, turn_el))
            )
            if creases[1] > creases[0]:
                best_az, best_el, best_iou, turned = turn_az, turn_el, turn_iou, True
    network = beliefs.most_likely()
    network_iou = float(
        silhouette_iou(
            shape, photo.mask, torch.tensor([network[0]]), torch.tensor([network[1]]), distance, fov, cfg.margin
        )[0]
    )
    source = "pose network + silhouette search" + (", turned half round by the creases" if turned else "")
    return PoseEstimate(best_az, best_el, source, network, round(best_iou, 4), round(network_iou, 4), creases, turned)


def estimate_pose(
    checkpoint: str | Path,
    shape: PreparedShape,
    photo: Photo,
    distance: float,
    fov: float,
    cfg: TransferConfig,
    device: torch.device,
) -> PoseEstimate:
    """``--pose auto``: the pose network's bins, refined by :func:`search_pose` unless ``cfg.pose_search`` is off.
    photo: image (1, 3, R, R), mask (1, 1, R, R)."""
    check_photo(photo, "estimate_pose")
    beliefs = pose_network_beliefs(checkpoint, photo, device)
    if cfg.pose_search:
        return search_pose(shape, photo, beliefs, distance, fov, cfg)
    azimuth, elevation = beliefs.most_likely()
    return PoseEstimate(azimuth, elevation, "pose network", (azimuth, elevation))


def pick_by_outline(photos: list[Photo], estimate) -> tuple[int, PoseEstimate]:
    """Among the same photo framed by several mask estimates, the one the mesh explains best: each is
    given to ``estimate`` (a photo -> :class:`PoseEstimate` with the search's ``silhouette_iou``) and
    the one whose found pose's silhouette matches its mask most wins (the first on ties). A wrong mask
    seldom matches any view of the right mesh. Returns its index and its estimate."""
    results = [estimate(photo) for photo in photos]
    best = max(range(len(results)), key=lambda i: results[i].silhouette_iou or 0.0)
    return best, results[best]


@dataclass
class Located:
    """Where the object is in the photo and where the camera was: the framed photo, where its mask came
    from, that mask (H, W) bool at the photo's size, and the pose."""

    photo: Photo
    mask_source: str
    mask: np.ndarray
    estimate: PoseEstimate


def locate_object(
    masked: MaskedPhoto,
    shape: PreparedShape,
    pose_checkpoint: str | Path | None,
    pose: tuple[float, float] | None,
    distance: float,
    fov: float,
    cfg: TransferConfig,
    device: torch.device,
) -> Located:
    """The object's mask and the pose of the mesh ``shape`` in a photo, each helping the other.

    ``pose`` (azimuth, elevation) given: used as it is. Else ``--pose auto`` (:func:`estimate_pose`);
    with several mask estimates, the one the mesh's outline matches best (:func:`pick_by_outline`).
    Then, unless the mask came with the photo or ``cfg.mask_refine`` is off, the mask is made again by
    GrabCut started from the mesh's outline at that pose and the mask network's probability (without
    a network, the picked estimate) (:func:`mesh2tex.transfer.mask.refine_with_outline`), and the pose
    found again from it (unless given). Measured on photos of meshes from outside the world
    (docs/results/transfer.md)."""
    photos = [frame_photo(masked.rgb, mask, cfg) for mask, _ in masked.masks]
    index = 0
    if pose is not None:
        estimate = PoseEstimate(pose[0], pose[1], "given")
    elif cfg.pose_search and len(photos) > 1:
        index, estimate = pick_by_outline(
            photos, lambda photo: estimate_pose(pose_checkpoint, shape, photo, distance, fov, cfg, device)
        )
    else:
        estimate = estimate_pose(pose_checkpoint, shape, photos[0], distance, fov, cfg, device)
    mask, source = masked.masks[index]
    if len(photos) > 1 and pose is None and cfg.pose_search:
        source += f", the one of {len(photos)} estimates the mesh's outline matched best"
    if masked.given or not cfg.mask_refine:
        return Located(photos[index], source, mask, estimate)
    box = object_box(mask, cfg.margin)
    outline = silhouette_in_photo(shape, estimate.azimuth, estimate.elevation, distance, fov, box, mask.shape, cfg)
    prior = masked.probability if masked.probability is not None else mask.astype(np.float32)
    refined = refine_with_outline(masked.rgb, outline, prior, box[2])
    if refined.sum() < 16:
        return Located(photos[index], source, mask, estimate)
    photo = frame_photo(masked.rgb, refined, cfg)
    if pose is None:
        estimate = estimate_pose(pose_checkpoint, shape, photo, distance, fov, cfg, device)
    return Located(photo, source + "; refined by GrabCut on the mesh's outline at the pose", refined, estimate)


@torch.no_grad()
def predict_noc(checkpoint: str | Path, photo: Photo, device: torch.device) -> torch.Tensor:
    """(R,R,3) NOC map of the photo (image (1, 3, R, R), mask (1, 1, R, R)) in [0,1], by the NOC network."""
    check_photo(photo, "predict_noc")
    net, cfg = load_view_network(checkpoint, "noc", device)
    size = cfg.data.resolution
    image = _network_input(photo, size, device)
    mask = F.interpolate(photo.mask.to(device), size=(size, size), mode="nearest")
    noc = net(image, mask)
    noc = F.interpolate(noc, size=photo.image.shape[-2:], mode="bilinear", align_corners=False)
    return noc[0].permute(1, 2, 0).cpu()


def _network_input(photo: Photo, size: int, device: torch.device) -> torch.Tensor:
    return F.interpolate(photo.image, size=(size, size), mode="area").to(device)
