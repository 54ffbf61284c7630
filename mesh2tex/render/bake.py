"""Baking a texture that lives on one surface onto the user's own mesh.

A generator's field (or an automaton's cells) lives on a working surface: the prepared quad mesh in
its normalised y-up frame, or the automaton's cell mesh in the unit ball. The user gets their own
mesh back (:class:`mesh2tex.geometry.mesh_io.UserMesh`: its vertices, faces, frame and units), with
UVs and a texture baked so:

1. the atlas: the mesh's own UVs when they are usable (:func:`uv_atlas_problem` finds none), else a
   new xatlas atlas over its triangles (vertices split on the new seams only);
2. for each texel, the point of the user's mesh under its centre is taken into the working
   surface's frame (up axis, then the normalisation) and mapped to the closest point of the working
   surface (:class:`mesh2tex.geometry.closest.SurfaceIndex`), where the texture's colour is read;
3. every texel no triangle covers takes the colour of the nearest covered one, so that bilinear and
   mip-mapped lookups never read an empty texel across a chart's border, at any mip level.

The same closest-point map gives the colour at each of the user's vertices (the PLY's colours).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import torch
from scipy import ndimage

from mesh2tex.errors import InputError
from mesh2tex.geometry.clean import Normalization
from mesh2tex.geometry.closest import SurfaceIndex
from mesh2tex.geometry.mesh_io import UserMesh
from mesh2tex.io.images import colours_to_uint8

from .interpolate import interpolate
from .surface_texture import SurfaceTexture, read_colours
from .uv import uv_atlas_problem, uv_rasterize

UV_MODES = ("auto", "keep", "new")


@dataclass
class BakeTarget:
    """The user's mesh, and the map of its points into the working surface's frame.

    mesh: the mesh as loaded; to_surface: the normalisation from its y-up working frame
    (:meth:`UserMesh.to_working_frame`) into the frame of the surface the texture lives on;
    uv: ``--uv`` auto (keep usable UVs, else a new atlas), keep or new.
    """

    mesh: UserMesh
    to_surface: Normalization
    uv: str = "auto"

    def surface_points(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) points in the file's frame -> (N, 3) float64 in the working surface's frame."""
        return self.to_surface.apply(self.mesh.to_working_frame(points))


@dataclass
class Atlas:
    """UVs for the user's mesh: vertex_index (V',) int64, the user's vertex each output vertex is (a
    vertex is split where the atlas has a seam); faces (T, 3) int64 into the output vertices, in the
    order and corner order of the user's faces; uv (V', 2) float64 in [0, 1], v up; source: 'kept' or
    'new'; note: why a new atlas was made ('' when the mesh's own UVs were kept or none were asked for)."""

    vertex_index: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    source: str
    note: str = ""


@dataclass
class BakedUserMesh:
    """The user's mesh with a baked texture, ready for :func:`mesh2tex.io.assets.save_glb`.

    vertices (V', 3) float64 in the file's frame and units; faces (T, 3) int64; uv (V', 2); normals
    (V', 3) the file's own, or None; texture (S, S, 3) uint8; coverage (S, S) bool (texels a triangle
    covers); vertex_colours (V, 3) uint8 at the user's own vertices; atlas: the :class:`Atlas`;
    surface_distance: (V,) float64, each user vertex's distance to the working surface (in its frame).
    """

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    normals: np.ndarray | None
    texture: np.ndarray
    coverage: np.ndarray
    vertex_colours: np.ndarray
    atlas: Atlas
    surface_distance: np.ndarray


class AtlasCrash(RuntimeError):
    """xatlas died on a mesh (a native crash in its own process), also after the retry."""


# The relative size of the shake given to the vertices that xatlas gets when it crashed on a mesh as it is
# (a perfectly regular subdivided icosphere of 82k faces crashes it; 1e-5 of the diagonal still does, 1e-3 not).
ATLAS_SHAKE = 1e-3


def _parametrize(points: np.ndarray, faces: np.ndarray):
    import xatlas

    return xatlas.parametrize(points, faces)


def parametrize_guarded(points: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``xatlas.parametrize(points (V, 3) float32, faces (T, 3) uint32)``, run where a native crash of xatlas
    cannot take this process with it (a forked process, where the platform forks; else here). When it dies,
    once more with every vertex moved by a random ``ATLAS_SHAKE`` of the bounding-box diagonal (the charts are
    cut on the shaken copy; the faces and corners stay the caller's); if that dies too, :class:`AtlasCrash`."""
    import multiprocessing
    import sys
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    if not sys.platform.startswith("linux"):  # no cheap fork: in this process
        return _parametrize(points, faces)
    diagonal = float(np.linalg.norm(points.max(0) - points.min(0))) if len(points) else 0.0
    shake = np.random.default_rng(0).uniform(-1, 1, points.shape) * ATLAS_SHAKE * diagonal
    for attempt in (points, (points + shake).astype(np.float32)):
        # Python 3.12+ warns of forking a process with threads (torch's); the child only runs xatlas
        with warnings.catch_warnings(), ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork")) as pool:
            warnings.simplefilter("ignore", DeprecationWarning)
            try:
                result = pool.submit(_parametrize, attempt, faces).result()
            except BrokenProcessPool:
                continue
        if attempt is not points:
            warnings.warn(
                f"xatlas crashed on the mesh as it is ({len(faces)} triangles); its charts were cut on a copy "
                f"with every vertex moved by up to {ATLAS_SHAKE:g} of its size (the faces and vertices kept)"
            )
        return result
    raise AtlasCrash(f"xatlas crashed on this mesh ({len(faces)} triangles), also with its vertices shaken")


def new_atlas(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An xatlas atlas over a triangle mesh whose coincident vertices are welded first (an STL file, or
    a mesh split on its old seams, would otherwise become one chart per triangle).

    vertices (V, 3), faces (T, 3) -> (vertex_index (V',) into ``vertices``, every vertex at least once
    (one no face uses at uv (0, 0)); faces (T, 3) in the given order and corner order; uv (V', 2)
    float64 in [0, 1], v up).
    """
    welded, weld = np.unique(np.asarray(vertices, dtype=np.float64), axis=0, return_inverse=True)
    weld = weld.reshape(-1)
    welded_faces = weld[faces]
    chart_vertex, chart_faces, chart_uv = parametrize_guarded(welded.astype(np.float32), welded_faces.astype(np.uint32))
    if chart_faces.shape != faces.shape or not np.array_equal(chart_vertex[chart_faces], welded_faces):
        raise RuntimeError("xatlas changed the face order or corners; baking needs them kept")
    # an output vertex per (user vertex, atlas vertex) pair met at a corner: user vertices stay apart
    # (their normals may differ), and are split only where the atlas has a seam
    pairs = np.stack([faces.reshape(-1), chart_faces.reshape(-1).astype(np.int64)], axis=1)
    unique, corner = np.unique(pairs, axis=0, return_inverse=True)
    uv = chart_uv[unique[:, 1]].astype(np.float64)
    # vertices no face uses are the user's too: kept, at uv (0, 0)
    unused = np.setdiff1d(np.arange(len(vertices)), unique[:, 0])
    return (
        np.concatenate([unique[:, 0], unused]),
        corner.reshape(faces.shape),
        np.concatenate([uv, np.zeros((len(unused), 2))]),
    )


def mesh_atlas(mesh: UserMesh, mode: str = "auto") -> Atlas:
    """The atlas ``--uv mode`` gives ``mesh``: keep (its own UVs, whatever they are), new (xatlas), or
    auto (its own when :func:`uv_atlas_problem` finds none, else new, with the reason in ``note``)."""
    if mode not in UV_MODES:
        raise ValueError(f"--uv {mode!r}: choose one of {', '.join(UV_MODES)}")
    if mode == "keep" and mesh.uv is None:
        raise InputError(f"{mesh.path}: --uv keep, but the mesh has no UV coordinates")
    note = ""
    if mode == "auto" and mesh.uv is not None:
        note = uv_atlas_problem(mesh.uv, mesh.faces)
    if mode == "keep" or (mode == "auto" and mesh.uv is not None and not note):
        return Atlas(np.arange(len(mesh.vertices)), mesh.faces.copy(), mesh.uv.copy(), "kept")
    try:
        vertex_index, faces, uv = new_atlas(mesh.vertices, mesh.faces)
    except AtlasCrash as error:
        raise InputError(f"{mesh.path}: {error}; give the mesh UVs of its own (--uv keep) or remesh it") from None
    if mode == "auto" and mesh.uv is None:
        note = "the mesh has no UV coordinates"
    return Atlas(vertex_index, faces, uv, "new", note)


def fill_empty_texels(colours: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """colours (H, W, C) with covered (H, W) bool: every uncovered texel takes the colour of the nearest
    covered one (returned as a new array; unchanged when nothing or everything is covered)."""
    if covered.all() or not covered.any():
        return colours.copy()
    _, (rows, cols) = ndimage.distance_transform_edt(~covered, return_indices=True)
    return colours[rows, cols]


def _colours(texture: SurfaceTexture, found, device) -> torch.Tensor:
    """The texture's colours at closest points ``found``, in chunks: (P, 3) float in [-1, 1] on the CPU."""
    return read_colours(texture, torch.from_numpy(found.triangle), torch.from_numpy(found.bary).float(), device)


class MeshBaker:
    """The map from a user's mesh to a working surface, made once (the atlas, each texel's and each
    vertex's closest surface point), then :meth:`bake` for each texture on that surface (several seeds).

    Args:
        target: the user's mesh and the map into the working surface's frame.
        surface_vertices: (V_s, 3) float, surface_triangles: (T_s, 3) int: the working surface, whose
            triangles the texture of :meth:`bake` is bound to.
        size: texture side in texels.
    """

    def __init__(self, target: BakeTarget, surface_vertices, surface_triangles, size: int):
        if size < 1:
            raise ValueError(f"MeshBaker: size must be positive, got {size}")
        self.target, self.size = target, int(size)
        mesh = target.mesh
        self.atlas = mesh_atlas(mesh, target.uv)
        index = SurfaceIndex(surface_vertices, surface_triangles)
        working = torch.from_numpy(target.surface_points(mesh.vertices)).float()  # (V, 3) in the surface's frame
        faces = torch.from_numpy(self.atlas.faces)
        raster = uv_rasterize(torch.from_numpy(self.atlas.uv).float(), faces, (self.size, self.size))
        self.coverage = (raster.face_id[0] >= 0).numpy()
        # (S, S, 3)
        texel_points = interpolate(working[torch.from_numpy(self.atlas.vertex_index)][None], raster, faces)[0]
        self._texels = index.query(texel_points.numpy()[self.coverage])
        self._vertices = index.query(working.numpy())

    @torch.no_grad()
    def bake(self, texture: SurfaceTexture, device: torch.device | str = "cpu") -> BakedUserMesh:
        """The user's mesh with ``texture`` (a :class:`~mesh2tex.render.surface_texture.SurfaceTexture` bound
        to the working surface, read on ``device``) baked into its atlas."""
        mesh, atlas = self.target.mesh, self.atlas
        colours = np.zeros((self.size, self.size, 3), dtype=np.float32)
        colours[self.coverage] = _colours(texture, self._texels, device).numpy()
        image = colours_to_uint8(torch.from_numpy(fill_empty_texels(colours, self.coverage)))
        normals = None if mesh.normals is None else mesh.normals[atlas.vertex_index]
        return BakedUserMesh(
            vertices=mesh.vertices[atlas.vertex_index],
            faces=atlas.faces,
            uv=atlas.uv,
            normals=normals,
            texture=image,
            coverage=self.coverage,
            vertex_colours=colours_to_uint8(_colours(texture, self._vertices, device)),
            atlas=atlas,
            surface_distance=self._vertices.distance,
        )
