"""A trained generator's texture on a prepared shape: latents, the shapes it can texture, its colours
at the mesh's vertices and its texture baked into UV space (for GLB files).

Rendering the texture in views is :func:`mesh2tex.nn.render_texture.render_field_views`; loading a
generator is :func:`mesh2tex.io.models.load_generator`.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import torch

from mesh2tex.errors import InputError
from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.io.assets import save_glb, save_ply, smooth_vertex_normals
from mesh2tex.io.images import colours_to_uint8
from mesh2tex.nn.batch import MeshBatch
from mesh2tex.nn.generator import FaceTexture, TextureGenerator
from mesh2tex.nn.render_texture import field_colours
from mesh2tex.render.uv import bake_surface_colours


def load_shape(path: str | Path, generator: TextureGenerator, face_count: int, seed: int = 0) -> PreparedShape:
    """A prepared shape from .npz, or a mesh file prepared on the fly (with a one-line warning on stderr
    when ``face_count`` is too coarse to keep its parts); checked against the generator."""
    path = Path(path)
    levels = generator.cfg.num_levels
    if path.suffix.lower() == ".npz":
        shape = PreparedShape.load(path)
    else:
        from mesh2tex.geometry.mesh_io import load_mesh
        from mesh2tex.geometry.prepare import coarseness_warning, prepare_shape

        vertices, faces = load_mesh(path)
        try:
            shape = prepare_shape(vertices, faces, face_count=face_count, levels=levels, seed=seed, source=str(path))
        except InputError as error:  # name the mesh the problem is in
            raise (error if str(error).startswith(str(path)) else InputError(f"{path}: {error}")) from None
        for warning in coarseness_warning(shape.metadata["coarseness"]):
            print(f"mesh2tex: warning: {path}: {warning}", file=sys.stderr)
    problem = shape_mismatch(shape, generator)
    if problem:
        raise InputError(f"{path}: has {problem}")
    return shape


def shape_mismatch(shape: PreparedShape, generator: TextureGenerator) -> str:
    """'' when the generator can texture ``shape``, else what differs, e.g. '2 levels, the generator needs 3'."""
    levels = generator.cfg.num_levels
    if shape.num_levels != levels:
        return f"{shape.num_levels} levels, the generator needs {levels}"
    if shape.face_features.shape[1] != generator.cfg.input_features:
        return f"{shape.face_features.shape[1]} face features, the generator needs {generator.cfg.input_features}"
    return ""


def latent(generator: TextureGenerator, seed: int, device: torch.device, truncation: float = 1.0) -> torch.Tensor:
    """ws (1, num_ws, w_dim) of latent seed ``seed`` (the same on every device)."""
    z = torch.randn(1, generator.cfg.z_dim, generator=torch.Generator().manual_seed(seed)).to(device)
    return generator.mapping(z, truncation_psi=truncation)


def mean_latent(generator: TextureGenerator) -> torch.Tensor:
    """ws (1, num_ws, w_dim): the mapping network's running mean ``w_avg`` at every style input (the mean texture)."""
    return generator.mapping.w_avg.reshape(1, 1, -1).expand(1, generator.num_ws, -1)


@torch.no_grad()
def bake_texture(generator: TextureGenerator, texture: FaceTexture, batch: MeshBatch, size: int, dilate: int = 8):
    """Bake psi into a UV texture for shape 0 of ``batch`` (:func:`mesh2tex.render.uv.bake_surface_colours`).

    Returns (vertices (V', 3) float32, faces (T, 3) int64, uv (V', 2) float32, texture (size, size, 3)
    uint8, coverage (size, size) bool). Faces keep the order of ``batch.triangles()``.
    """
    device = texture.face_rgb.device

    def colours_at(triangle_id: torch.Tensor, bary: torch.Tensor) -> torch.Tensor:
        return field_colours(generator, texture, batch, triangle_id.to(device), bary.to(device))

    return bake_surface_colours(batch.shape_vertices(0), batch.shape_triangles(0), colours_at, size, dilate)


@torch.no_grad()
def vertex_colours(generator: TextureGenerator, texture: FaceTexture, batch: MeshBatch) -> np.ndarray:
    """(V, 3) uint8 colours of shape 0's finest vertices: psi at each corner of each incident triangle, averaged."""
    triangles = batch.shape_triangles(0)
    t = triangles.shape[0]
    triangle_id = torch.arange(t, device=triangles.device).repeat_interleave(3) + 2 * batch.face_ranges[0][0]
    bary = torch.eye(3, device=triangles.device).repeat(t, 1)
    colours = field_colours(generator, texture, batch, triangle_id, bary).float()  # (3T, 3)
    v = batch.shape_vertices(0).shape[0]
    index = triangles.reshape(-1)
    summed = torch.zeros(v, 3, device=colours.device).index_add_(0, index, colours)
    counts = torch.zeros(v, device=colours.device).index_add_(0, index, torch.ones_like(index, dtype=torch.float32))
    mean = summed / counts.clamp(min=1).unsqueeze(1)
    return colours_to_uint8(mean)


@torch.no_grad()
def write_textured_mesh(glb_path: str | Path, ply_path: str | Path, generator: TextureGenerator, texture: FaceTexture,
                        batch: MeshBatch, texture_size: int, texture_format: str = "png") -> None:
    """Shape 0 of ``batch`` with ``texture``: a GLB with the texture baked into a ``texture_size``
    square UV map (:func:`bake_texture`), embedded as ``texture_format`` (png, jpeg or webp; see
    :func:`mesh2tex.io.assets.save_glb`), and a PLY with :func:`vertex_colours`."""
    verts, faces, uv, image, _ = bake_texture(generator, texture, batch, texture_size)
    save_glb(glb_path, verts.numpy(), faces.numpy(), uv.numpy(), image, smooth_vertex_normals(verts.numpy(), faces.numpy()),
             texture_format=texture_format)
    save_ply(ply_path, batch.shape_vertices(0).cpu().numpy(), batch.shape_triangles(0).cpu().numpy(),
             vertex_colours(generator, texture, batch))


@torch.no_grad()
def write_automaton_mesh(glb_path: str | Path, ply_path: str | Path, model, state: torch.Tensor, graph, texture_size: int,
                         texture_format: str = "png", graft=None) -> None:
    """An automaton's growth on its mesh: a GLB with the readout baked into a ``texture_size`` square UV
    map (``texture_format`` as :func:`write_textured_mesh`), and a PLY with the colour at each cell.

    model: :class:`mesh2tex.nn.nca.MeshNCA`; state (1, V, C) on the model's device; graph: its
    :class:`~mesh2tex.nn.nca.CellGraph`; graft: (other automaton, alpha (V,)) as in ``MeshNCA.colours``.
    """
    device = state.device

    def colours_at(triangle_id: torch.Tensor, bary: torch.Tensor) -> torch.Tensor:
        return model.colours(state, graph.triangles, triangle_id.to(device), bary.to(device), graft=graft)

    verts, tris, uv, image, _ = bake_surface_colours(graph.positions, graph.triangles, colours_at, texture_size)
    save_glb(glb_path, verts.numpy(), tris.numpy(), uv.numpy(), image, smooth_vertex_normals(verts.numpy(), tris.numpy()),
             texture_format=texture_format)
    save_ply(ply_path, graph.positions.cpu().numpy(), graph.triangles.cpu().numpy(), colours_to_uint8(model.vertex_colours(state, graft=graft)[0]))
