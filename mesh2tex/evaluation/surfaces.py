"""Textured surfaces to compare: a mesh and a colour for every point of it.

Every candidate of a quality table (the transfer's result, the simple baselines, the ground truth)
is a :class:`Surface`, so one function (:func:`mesh2tex.evaluation.render_for_comparison`) renders
them all alike. A surface's ``colour`` maps the surface points a render sees (:class:`SurfacePoints`)
to albedo in [0, 1]:

* :func:`textured_surface`: a UV texture (a GLB: the world's ground truth, the transfer's export);
* :func:`flat_surface`: one colour everywhere (the photo's mean colour baseline);
* :func:`material_surface`: a synthetic world's procedural material (the exact ground truth, also
  on another shape of the category: the material is a function of 3D points and part labels);
* :func:`generator_surface`: the neural field psi on a generator's face features (a transfer
  result, or the mean texture of ``w_avg``), evaluated exactly as the GAN renders it;
* :func:`backprojected_surface`: the photo projected onto the mesh from the photo's camera, each
  unseen point taking the colour of the nearest seen one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch
import torch.nn.functional as F

from mesh2tex.render import interpolate, rasterize, transform_points
from mesh2tex.render.surface_texture import UVTexture


@dataclass
class SurfacePoints:
    """Surface points seen by P covered (sub-)pixels.

    face    [P] int64      index into the surface's faces
    bary    [P, 3] float32 barycentrics of the face's corners
    points  [P, 3] float32 world-space positions
    normals [P, 3] float32 unit face normals
    """

    face: torch.Tensor
    bary: torch.Tensor
    points: torch.Tensor
    normals: torch.Tensor


@dataclass
class Surface:
    """A triangle mesh with a colour at every point.

    vertices   [V, 3] float32, the normalised frame of the world (bbox centre 0, diagonal 1)
    faces      [T, 3] int64
    colour     SurfacePoints -> [P, 3] float32 albedo in [0, 1]
    face_parts [T] int64 part label of each face (e.g. ``PART_NAMES`` indices), or None when unknown
    """

    vertices: torch.Tensor
    faces: torch.Tensor
    colour: Callable[[SurfacePoints], torch.Tensor]
    face_parts: torch.Tensor | None = None

    def __post_init__(self):
        self.vertices = torch.as_tensor(
            np.asarray(self.vertices) if not torch.is_tensor(self.vertices) else self.vertices, dtype=torch.float32
        )
        self.faces = torch.as_tensor(
            np.asarray(self.faces) if not torch.is_tensor(self.faces) else self.faces, dtype=torch.int64
        )
        if self.vertices.dim() != 2 or self.vertices.shape[1] != 3:
            raise ValueError(f"vertices must be [V, 3], got {tuple(self.vertices.shape)}")
        if self.faces.dim() != 2 or self.faces.shape[1] != 3:
            raise ValueError(f"faces must be [T, 3], got {tuple(self.faces.shape)}")
        if self.face_parts is not None:
            self.face_parts = torch.as_tensor(np.asarray(self.face_parts), dtype=torch.int64).reshape(-1)
            if self.face_parts.shape[0] != self.faces.shape[0]:
                raise ValueError(f"face_parts has {self.face_parts.shape[0]} entries for {self.faces.shape[0]} faces")


def with_parts(surface: Surface, face_parts) -> Surface:
    """The same surface with part labels (faces in the same order as ``face_parts``)."""
    return Surface(surface.vertices, surface.faces, surface.colour, face_parts)


def flat_surface(vertices, faces, rgb, face_parts=None) -> Surface:
    """One colour ``rgb`` (3,) in [0, 1] everywhere."""
    colour = torch.as_tensor(rgb, dtype=torch.float32).reshape(1, 3)
    return Surface(vertices, faces, lambda p: colour.expand(p.face.shape[0], 3), face_parts)


def textured_surface(vertices, faces, uv, image, face_parts=None) -> Surface:
    """A UV-textured mesh: uv [V, 2] (u right, v up, ``mesh2tex.render.texture``'s convention),
    image [H, W, 3] uint8 or float in [0, 1]; bilinear lookups."""
    uv = torch.as_tensor(np.asarray(uv), dtype=torch.float32)
    image = torch.as_tensor(np.array(image))  # a copy: the caller's array may be read-only
    image = (image.float() / 255.0 if image.dtype == torch.uint8 else image.float()).permute(2, 0, 1).contiguous()
    surface = Surface(vertices, faces, lambda p: p.face, face_parts)  # colour set below, once faces are tensors
    if uv.shape != (surface.vertices.shape[0], 2):
        raise ValueError(f"uv must be [V, 2] = [{surface.vertices.shape[0]}, 2], got {tuple(uv.shape)}")
    uv_texture = UVTexture(uv[surface.faces], image[None] * 2.0 - 1.0)
    surface.colour = lambda p: ((uv_texture.colours(p.face, p.bary) + 1.0) * 0.5).clamp(0, 1)
    return surface


def vertex_colour_surface(vertices, faces, colours, face_parts=None) -> Surface:
    """Colours [V, 3] in [0, 1] at the vertices, interpolated over each face."""
    colours = torch.as_tensor(np.asarray(colours), dtype=torch.float32)
    surface = Surface(vertices, faces, lambda p: p.face, face_parts)
    tri = surface.faces
    surface.colour = lambda p: (colours[tri[p.face]] * p.bary[..., None]).sum(1)
    return surface


def material_surface(vertices, faces, face_parts, material) -> Surface:
    """A procedural material (``mesh2tex.synthetic.materials.Material``: points, normals, part ids ->
    rgb) on a mesh whose faces carry part labels (``PART_NAMES`` indices)."""
    parts = torch.as_tensor(np.asarray(face_parts), dtype=torch.int64)

    def colour(p: SurfacePoints) -> torch.Tensor:
        rgb = material(p.points.double().numpy(), p.normals.double().numpy(), parts[p.face].numpy())
        return torch.as_tensor(rgb, dtype=torch.float32)

    return Surface(vertices, faces, colour, parts)


def generator_surface(generator, texture, batch, face_parts=None) -> Surface:
    """psi of ``generator`` on shape 0 of ``batch`` (a ``MeshBatch`` of one prepared shape) with the
    generator's output ``texture`` (a ``FaceTexture`` from ``generator.synthesize``: face features
    [F_0, C] and per-face colours [F_0, 3], which psi's residual output is added to; the transfer's
    refinement changes only the synthesis blocks, so these two are the whole result)."""
    from mesh2tex.nn.generator import FaceTexture

    if batch.num_shapes != 1:
        raise ValueError(f"generator_surface takes a batch of one shape, got {batch.num_shapes}")
    device = next(generator.parameters()).device
    faces = batch.shape_triangles(0).cpu()
    face_texture = FaceTexture(texture.field_features.detach().to(device), texture.face_rgb.detach().to(device)).bound(
        generator, batch.to(device)
    )

    @torch.no_grad()
    def colour(p: SurfacePoints) -> torch.Tensor:
        if p.face.numel() == 0:
            return torch.zeros(0, 3)
        rgb = face_texture.colours(p.face.to(device), p.bary.to(device)).float().cpu()
        return ((rgb + 1.0) * 0.5).clamp(0, 1)

    return Surface(batch.shape_vertices(0).cpu(), faces, colour, face_parts)


def _to_pixels(points: torch.Tensor, mvp: torch.Tensor, size: int) -> tuple[torch.Tensor, torch.Tensor]:
    """World points [P, 3] -> continuous pixel coordinates (row, col) [P] of a size x size render
    (pixel centres at i + 0.5, row 0 the top) and clip w [P]."""
    clip = transform_points(points, mvp.reshape(1, 4, 4))[0]
    w = clip[:, 3].clamp_min(1e-8)
    col = (clip[:, 0] / w + 1.0) * 0.5 * size
    row = (1.0 - clip[:, 1] / w) * 0.5 * size
    return row, col


def backprojected_surface(
    vertices,
    faces,
    image: torch.Tensor,
    mask: torch.Tensor,
    mvp: torch.Tensor,
    render_size: int,
    box: tuple[int, int, int],
    tolerance: float = 0.02,
    face_parts=None,
) -> Surface:
    """The photo painted onto the mesh from the photo's camera ("photo back-projection").

    image [3, R, R] in [0, 1] and mask [R, R] {0, 1}: the photo cropped around its object, as the
    transfer sees it; ``mvp`` [1, 4, 4] or [4, 4] the camera, ``render_size`` the side of the full
    render it frames and ``box`` (top, left, side) the square of that render the crop shows (an
    ``mesh2tex.transfer.FramedView``: true or estimated pose). A surface point the camera sees (it is within
    ``tolerance`` of the surface point its pixel shows, and the photo's mask covers it) takes the
    photo's colour at its projection (bilinear over object pixels only); any other point takes the
    colour of the nearest such seen point.
    """
    from scipy.spatial import cKDTree

    surface = Surface(vertices, faces, lambda p: p.face, face_parts)
    verts, tri = surface.vertices, surface.faces
    mvp = torch.as_tensor(mvp, dtype=torch.float32).reshape(1, 4, 4)
    image = torch.as_tensor(image, dtype=torch.float32)
    mask = torch.as_tensor(mask, dtype=torch.float32).reshape(image.shape[-2:])
    if image.dim() != 3 or image.shape[0] != 3:
        raise ValueError(f"image must be [3, R, R], got {tuple(image.shape)}")
    crop = image.shape[-1]
    top, left, side = box
    stacked = torch.cat([image * mask, mask[None]], dim=0)[None]  # [1, 4, R, R]

    def photo_at(row: torch.Tensor, col: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Render-pixel coordinates -> (photo colour [P, 3], object weight [P]) through the crop box."""
        y = (row - top) * crop / side
        x = (col - left) * crop / side
        grid = torch.stack([x / crop * 2 - 1, y / crop * 2 - 1], dim=-1).reshape(1, 1, -1, 2)
        sampled = F.grid_sample(stacked, grid, mode="bilinear", padding_mode="zeros", align_corners=False)[0, :, 0].T
        weight = sampled[:, 3]
        return sampled[:, :3] / weight.clamp_min(1e-6)[:, None], weight

    raster = rasterize(transform_points(verts, mvp), tri, (render_size, render_size))
    seen_points = interpolate(verts, raster, tri)[0]  # [S, S, 3]
    covered = raster.face_id[0] >= 0
    rows, cols = torch.nonzero(covered, as_tuple=True)
    colours, weight = photo_at(rows.float() + 0.5, cols.float() + 0.5)
    keep = weight >= 0.5
    if int(keep.sum()) == 0:
        raise ValueError("back-projection: the photo's mask and the mesh's silhouette at this pose do not overlap")
    cloud = seen_points[rows[keep], cols[keep]]
    cloud_colours = colours[keep].clamp(0, 1)
    tree = cKDTree(cloud.double().numpy())

    def colour(p: SurfacePoints) -> torch.Tensor:
        out = torch.empty(p.points.shape[0], 3)
        if p.points.shape[0] == 0:
            return out
        row, col = _to_pixels(p.points, mvp, render_size)
        r, c = row.floor().long(), col.floor().long()
        inside = (r >= 0) & (r < render_size) & (c >= 0) & (c < render_size)
        r, c = r.clamp(0, render_size - 1), c.clamp(0, render_size - 1)
        near = (seen_points[r, c] - p.points).norm(dim=1) < tolerance
        direct, direct_weight = photo_at(row, col)
        visible = inside & covered[r, c] & near & (direct_weight >= 0.5)
        out[visible] = direct[visible].clamp(0, 1)
        hidden = ~visible
        if hidden.any():
            _, index = tree.query(p.points[hidden].double().numpy())
            out[hidden] = cloud_colours[torch.as_tensor(index, dtype=torch.int64)]
        return out

    surface.colour = colour
    return surface


@torch.no_grad()
def backproject_photo(
    vertices,
    faces,
    photo: torch.Tensor,
    photo_mask: torch.Tensor,
    azimuth: float,
    elevation: float,
    distance: float,
    fov: float,
    align: str = "silhouette",
    margin: float = 0.1,
    face_parts=None,
) -> Surface:
    """:func:`backprojected_surface` from a whole photo and an orbit pose (degrees), framed like the transfer.

    photo [3, H, H] in [0, 1], photo_mask [H, H] {0, 1}. ``align="photo"``: the pose is the photo's
    own camera (a known pose), so photo pixels and render pixels coincide. ``align="silhouette"``: an
    estimated pose (whose distance and field of view may differ from the photo's): the photo is
    framed by its object's square box and the mesh by its silhouette's, both with ``margin``, the way
    ``infer transfer`` lines them up.
    """
    from mesh2tex.render import crop_mask, crop_square, object_box, orbit_camera

    photo = torch.as_tensor(photo, dtype=torch.float32)
    mask = torch.as_tensor(np.asarray(photo_mask), dtype=torch.float32).reshape(photo.shape[-2:])
    side = int(photo.shape[-1])
    camera = orbit_camera(
        torch.tensor([float(azimuth)]), torch.tensor([float(elevation)]), distance=float(distance), fov=float(fov)
    )
    if align == "photo":
        return backprojected_surface(
            vertices, faces, photo, mask, camera.mvp, side, (0, 0, side), face_parts=face_parts
        )
    if align != "silhouette":
        raise ValueError(f"align must be 'photo' or 'silhouette', got {align!r}")
    box = object_box(mask.numpy() > 0.5, margin)
    crop = crop_square(photo[None], box, side, fill=1.0)[0]
    crop_m = crop_mask(mask > 0.5, box, side)[0, 0]
    render_size = int(round(side * 1.5))
    verts = torch.as_tensor(np.asarray(vertices), dtype=torch.float32)
    tri = torch.as_tensor(np.asarray(faces), dtype=torch.int64)
    covered = (rasterize(transform_points(verts, camera.mvp), tri, (render_size, render_size)).face_id[0] >= 0).numpy()
    if covered.sum() < 4:
        raise ValueError(f"the mesh is not visible at azimuth {azimuth}, elevation {elevation} (distance {distance})")
    return backprojected_surface(
        verts, tri, crop, crop_m, camera.mvp, render_size, object_box(covered, margin), face_parts=face_parts
    )


def photo_mean_colour(image: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean colour [3] of the object pixels: image [3, H, W] in [0, 1], mask [H, W] (or [1, H, W]) {0, 1}."""
    mask = torch.as_tensor(mask, dtype=torch.float32).reshape(image.shape[-2:])
    total = mask.sum()
    if total < 1:
        raise ValueError("the photo's object mask is empty")
    return (image * mask).sum(dim=(1, 2)) / total
