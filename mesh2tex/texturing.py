"""A trained generator's texture on a shape: latents, the shapes it can texture (a user's mesh with
its prepared working copy, :func:`load_shape`), its colours at the mesh's vertices and the textured
assets written: the user's own mesh with the texture baked into its atlas
(:mod:`mesh2tex.render.bake`), or the prepared shape itself.

Rendering the texture in views is :func:`mesh2tex.nn.render_texture.render_field_views`; loading a
generator is :func:`mesh2tex.models.load_generator`; a note to the user, :func:`mesh2tex.errors.note`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from mesh2tex.errors import InputError, note, warning
from mesh2tex.geometry.mesh_io import UserMesh
from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.io.assets import save_glb, save_ply, smooth_vertex_normals
from mesh2tex.io.images import colours_to_uint8
from mesh2tex.nn.batch import MeshBatch
from mesh2tex.nn.generator import FaceTexture, TextureGenerator
from mesh2tex.nn.nca import AutomatonTexture
from mesh2tex.render.bake import BakedUserMesh, BakeTarget, MeshBaker
from mesh2tex.render.uv import bake_surface_colours


def read_user_mesh(path: str | Path, up: str = "auto") -> UserMesh:
    """:func:`~mesh2tex.geometry.mesh_io.load_user_mesh`, with a note on stderr saying which axis is up and why."""
    from mesh2tex.geometry.mesh_io import load_user_mesh

    mesh = load_user_mesh(path, up)
    note(f"{path}: {mesh.up}-up ({mesh.up_reason})")
    return mesh


def source_mesh(shape: PreparedShape, path: str | Path, instead: str) -> UserMesh | None:
    """The mesh a prepared shape (read from ``path``) was made from, read with its recorded up axis;
    None, with a note that ``instead`` is written, when its file is not where the record says."""
    from mesh2tex.geometry.mesh_io import load_user_mesh

    source = str(shape.metadata.get("source") or "")
    if source and Path(source).is_file():
        return load_user_mesh(source, str(shape.metadata.get("up", "y")))
    note(f"{path}: its source mesh {source or '(none recorded)'} is not found; writing {instead}")
    return None


def load_shape(
    path: str | Path,
    generator: TextureGenerator,
    face_count: int,
    seed: int = 0,
    up: str = "auto",
    uv: str = "auto",
    output_mesh: str = "input",
) -> tuple[PreparedShape, BakeTarget | None]:
    """The shape a command textures, and where its texture goes.

    ``path`` is a mesh file, prepared on the fly (a one-line warning on stderr when ``face_count`` is too
    coarse to keep its parts), or a prepared shape (.npz). Returns (the prepared shape, checked against
    the generator; the user's mesh as a :class:`~mesh2tex.render.bake.BakeTarget` with ``--uv uv``, or
    None for ``output_mesh`` 'prepared', or for a prepared shape whose source mesh is not found: then
    the prepared shape itself is written, and a note says so). ``up``: the file's up axis
    (:func:`~mesh2tex.geometry.mesh_io.choose_up`; a prepared shape has its own on record).
    """
    from mesh2tex.geometry.clean import Normalization

    if output_mesh not in ("input", "prepared"):
        raise InputError(f"--output-mesh {output_mesh!r}: choose input or prepared")
    path = Path(path)
    mesh = None
    if path.suffix.lower() == ".npz":
        shape = PreparedShape.load(path)
        if output_mesh == "input":
            mesh = source_mesh(shape, path, "the prepared shape")
    else:
        from mesh2tex.geometry.prepare import coarseness_warning, prepare_user_mesh

        mesh = read_user_mesh(path, up)
        shape = prepare_user_mesh(mesh, face_count=face_count, levels=generator.cfg.num_levels, seed=seed)
        for problem in coarseness_warning(shape.metadata["coarseness"]):
            warning(f"{path}: {problem}")
        if output_mesh == "prepared":
            mesh = None
    problem = shape_mismatch(shape, generator)
    if problem:
        raise InputError(f"{path}: has {problem}")
    if mesh is None:
        return shape, None
    try:
        transform = Normalization.from_json(shape.metadata.get("transform"))
    except ValueError as error:
        raise InputError(f"{path}: its normalisation transform is {error}") from None
    return shape, BakeTarget(mesh, transform, uv)


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
    return bake_surface_colours(
        batch.shape_vertices(0),
        batch.shape_triangles(0),
        texture.bound(generator, batch),
        size,
        dilate,
        device=texture.face_rgb.device,
    )


@torch.no_grad()
def vertex_colours(generator: TextureGenerator, texture: FaceTexture, batch: MeshBatch) -> np.ndarray:
    """(V, 3) uint8 colours of shape 0's finest vertices: psi at each corner of each incident triangle, averaged."""
    triangles = batch.shape_triangles(0)
    t = triangles.shape[0]
    triangle_id = torch.arange(t, device=triangles.device).repeat_interleave(3) + 2 * batch.face_ranges[0][0]
    bary = torch.eye(3, device=triangles.device).repeat(t, 1)
    colours = texture.bound(generator, batch).colours(triangle_id, bary).float()  # (3T, 3)
    v = batch.shape_vertices(0).shape[0]
    index = triangles.reshape(-1)
    summed = torch.zeros(v, 3, device=colours.device).index_add_(0, index, colours)
    counts = torch.zeros(v, device=colours.device).index_add_(0, index, torch.ones_like(index, dtype=torch.float32))
    mean = summed / counts.clamp(min=1).unsqueeze(1)
    return colours_to_uint8(mean)


def write_baked_mesh(
    glb_path: str | Path, ply_path: str | Path, baked: BakedUserMesh, mesh: UserMesh, texture_format: str = "png"
) -> dict:
    """The user's mesh with its baked texture: a GLB (the file's vertex positions as they are, split on
    the atlas's seams; a z-up mesh's node stands it up, see :func:`mesh2tex.io.assets.save_glb`) with
    the file's normals, or smooth ones when it has none, and a PLY of the user's own vertices and faces
    with the texture's colour at each vertex. Returns what a report says of the mesh written."""
    normals = baked.normals if baked.normals is not None else smooth_vertex_normals(baked.vertices, baked.faces)
    save_glb(
        glb_path,
        baked.vertices,
        baked.faces,
        baked.uv,
        baked.texture,
        normals,
        texture_format=texture_format,
        up_axis=mesh.up,
    )
    save_ply(ply_path, mesh.vertices, mesh.faces, baked.vertex_colours)
    return {
        "mesh": "input",
        "up": mesh.up,
        "vertices": int(len(baked.vertices)),
        "triangles": int(len(baked.faces)),
        "uv": baked.atlas.source,
        "uv_note": baked.atlas.note,
        "surface_distance_max": round(float(baked.surface_distance.max()), 5) if len(baked.surface_distance) else 0.0,
    }


class TexturedMeshWriter:
    """Writes a generator's textures on shape 0 of ``batch`` as GLB + PLY: baked onto the user's mesh
    (``target``; the map to it made once, for every texture written) or, when ``target`` is None, onto
    the prepared shape itself (a fresh xatlas atlas over its finest triangles, :func:`bake_texture`)."""

    def __init__(
        self,
        generator: TextureGenerator,
        batch: MeshBatch,
        target: BakeTarget | None,
        texture_size: int,
        texture_format: str = "png",
    ):
        self.generator, self.batch, self.target = generator, batch, target
        self.texture_size, self.texture_format = int(texture_size), texture_format
        self.baker = (
            None
            if target is None
            else MeshBaker(target, batch.shape_vertices(0).cpu(), batch.shape_triangles(0).cpu(), texture_size)
        )

    @property
    def uv_note(self) -> str:
        """Why the user's own UVs were not kept ('' when they were, or none were asked for)."""
        return "" if self.baker is None else self.baker.atlas.note

    @torch.no_grad()
    def write(self, glb_path: str | Path, ply_path: str | Path, texture: FaceTexture) -> dict:
        """Both files for ``texture``; returns what a report says of the mesh written."""
        generator, batch = self.generator, self.batch
        if self.baker is None:
            verts, faces, uv, image, _ = bake_texture(generator, texture, batch, self.texture_size)
            save_glb(
                glb_path,
                verts.numpy(),
                faces.numpy(),
                uv.numpy(),
                image,
                smooth_vertex_normals(verts.numpy(), faces.numpy()),
                texture_format=self.texture_format,
            )
            save_ply(
                ply_path,
                batch.shape_vertices(0).cpu().numpy(),
                batch.shape_triangles(0).cpu().numpy(),
                vertex_colours(generator, texture, batch),
            )
            return {"mesh": "prepared", "vertices": int(len(verts)), "triangles": int(len(faces)), "uv": "new"}
        baked = self.baker.bake(texture.bound(generator, batch), texture.face_rgb.device)
        return write_baked_mesh(glb_path, ply_path, baked, self.target.mesh, self.texture_format)


@torch.no_grad()
def write_textured_mesh(
    glb_path: str | Path,
    ply_path: str | Path,
    generator: TextureGenerator,
    texture: FaceTexture,
    batch: MeshBatch,
    texture_size: int,
    texture_format: str = "png",
    target: BakeTarget | None = None,
) -> dict:
    """One texture written by a :class:`TexturedMeshWriter` (see there); returns what a report says of the mesh."""
    return TexturedMeshWriter(generator, batch, target, texture_size, texture_format).write(glb_path, ply_path, texture)


@torch.no_grad()
def write_automaton_mesh(
    glb_path: str | Path,
    ply_path: str | Path,
    model,
    state: torch.Tensor,
    graph,
    texture_size: int,
    texture_format: str = "png",
    graft=None,
    target: BakeTarget | None = None,
) -> dict:
    """An automaton's growth: baked onto the user's mesh (``target``, whose ``to_surface`` maps into the
    cell mesh's frame), or, without one, onto the cell mesh itself (an xatlas atlas over its triangles)
    with a PLY of the colour at each cell. ``texture_format`` as :func:`write_textured_mesh`.

    model: :class:`mesh2tex.nn.nca.MeshNCA`; state (1, V, C) on the model's device; graph: its
    :class:`~mesh2tex.nn.cell_graph.CellGraph`; graft: (other automaton, alpha (V,)) as in ``MeshNCA.colours``.
    Returns what a report says of the mesh written.
    """
    grown = AutomatonTexture(model, state, graph.triangles, graft)
    if target is not None:
        baked = MeshBaker(target, graph.positions.cpu(), graph.triangles.cpu(), texture_size).bake(grown, state.device)
        return write_baked_mesh(glb_path, ply_path, baked, target.mesh, texture_format)
    verts, tris, uv, image, _ = bake_surface_colours(
        graph.positions, graph.triangles, grown, texture_size, device=state.device
    )
    save_glb(
        glb_path,
        verts.numpy(),
        tris.numpy(),
        uv.numpy(),
        image,
        smooth_vertex_normals(verts.numpy(), tris.numpy()),
        texture_format=texture_format,
    )
    save_ply(
        ply_path,
        graph.positions.cpu().numpy(),
        graph.triangles.cpu().numpy(),
        colours_to_uint8(model.vertex_colours(state, graft=graft)[0]),
    )
    return {"mesh": "prepared", "vertices": int(len(verts)), "triangles": int(len(tris)), "uv": "new"}
