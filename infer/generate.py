"""``mesh2tex infer generate``: texture a mesh from random latent codes with a trained GAN.

    mesh2tex infer generate --checkpoint RUN/checkpoint.safetensors --mesh MESH_OR_NPZ --out DIR
                            [--seeds 0,1,2] [--views 8] [--resolution 512] [--texture-size 1024]

Writes, per seed S: ``seed{S}_view{V}.png`` (orbit views, azimuths evenly spaced), ``seed{S}.glb``
(the finest quad level, split into triangles, with a UV texture baked from psi: xatlas unwrapping,
UV-space rasterization, seams dilated) and ``seed{S}.ply`` (vertex colours). A raw mesh is
prepared on the fly (``mesh2tex prepare shapes`` does the same ahead of time). Assets are in the
prepared shape's normalised frame (bounding-box centre at the origin, diagonal 1).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from mesh2tex.errors import UserError
from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.io.checkpoint import load_checkpoint
from mesh2tex.nn.batch import MeshBatch, collate_shapes
from mesh2tex.nn.generator import FaceTexture, GeneratorConfig, TextureGenerator
from mesh2tex.nn.render_texture import field_colors, render_field_views
from mesh2tex.render import orbit_camera
from train.gan import sample_views, save_png, to_uint8
from train.runs import select_device


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--checkpoint", required=True, help="GAN checkpoint (RUN/checkpoint.safetensors) or a shipped model's name (chair, car)")
    parser.add_argument("--mesh", required=True, help="a prepared shape (.npz) or a mesh file (.obj .ply .off .stl .glb)")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--seeds", default="0,1,2", help="comma-separated latent seeds (default 0,1,2)")
    parser.add_argument("--views", type=int, default=8, help="orbit views per seed (default 8)")
    parser.add_argument("--resolution", type=int, default=512, help="render resolution (default 512)")
    parser.add_argument("--texture-size", type=int, default=1024, help="baked UV texture size (default 1024)")
    parser.add_argument("--elevation", type=float, default=20.0, help="elevation of the orbit views, degrees (default 20)")
    parser.add_argument("--truncation", type=float, default=1.0, help="truncation psi of the latent (1: none)")
    parser.add_argument("--faces", type=int, default=6144, help="finest quad count when preparing a raw mesh (default 6144)")
    parser.add_argument("--device", choices=["auto", "cpu", "cuda"], default="auto", help="where to run")


def load_generator(path: str | Path, device: torch.device) -> tuple[TextureGenerator, dict]:
    """The EMA generator of a GAN checkpoint (a path, or a shipped model's name such as ``chair``), in
    eval mode, and the checkpoint's metadata."""
    from mesh2tex.config import config_from_dict
    from mesh2tex.io.models import resolve_checkpoint

    path = resolve_checkpoint(path, "gan")
    groups, meta = load_checkpoint(path, kind="gan")
    saved = dict(meta["generator_config"])
    saved.setdefault("field_residual", False)  # written before psi became a residual on the proxy colours
    cfg = config_from_dict(GeneratorConfig, saved, f"{path}: generator_config")
    generator = TextureGenerator(cfg)
    try:
        generator.load_state_dict(groups["generator_ema"])
    except (KeyError, RuntimeError) as error:
        raise UserError(f"{path}: generator weights missing or damaged ({str(error).splitlines()[0]})") from None
    return generator.to(device).eval().requires_grad_(False), meta


def load_shape(path: str | Path, generator: TextureGenerator, face_count: int, seed: int = 0) -> PreparedShape:
    """A prepared shape from .npz, or a mesh file prepared on the fly; checked against the generator."""
    path = Path(path)
    levels = generator.cfg.num_levels
    if path.suffix.lower() == ".npz":
        shape = PreparedShape.load(path)
    else:
        from mesh2tex.geometry.mesh_io import load_mesh
        from mesh2tex.geometry.prepare import prepare_shape

        vertices, faces = load_mesh(path)
        shape = prepare_shape(vertices, faces, face_count=face_count, levels=levels, seed=seed, source=str(path))
    problem = shape_mismatch(shape, generator)
    if problem:
        raise UserError(f"{path}: has {problem}")
    return shape


def shape_mismatch(shape: PreparedShape, generator: TextureGenerator) -> str:
    """'' when the generator can texture ``shape``, else what differs, e.g. '2 levels, the generator needs 3'."""
    levels = generator.cfg.num_levels
    if shape.num_levels != levels:
        return f"{shape.num_levels} levels, the generator needs {levels}"
    if shape.face_features.shape[1] != generator.cfg.input_features:
        return f"{shape.face_features.shape[1]} face features, the generator needs {generator.cfg.input_features}"
    return ""


def parse_seeds(text: str) -> list[int]:
    try:
        seeds = [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise UserError(f"--seeds {text!r}: expected comma-separated integers, e.g. 0,1,2") from None
    if not seeds:
        raise UserError("--seeds: give at least one seed")
    return seeds


def latent(generator: TextureGenerator, seed: int, device: torch.device, truncation: float = 1.0) -> torch.Tensor:
    """ws (1, num_ws, w_dim) of latent seed ``seed`` (the same on every device)."""
    z = torch.randn(1, generator.cfg.z_dim, generator=torch.Generator().manual_seed(seed)).to(device)
    return generator.mapping(z, truncation_psi=truncation)


@torch.no_grad()
def bake_texture(generator: TextureGenerator, texture: FaceTexture, batch: MeshBatch, size: int, dilate: int = 8):
    """Bake psi into a UV texture for shape 0 of ``batch``.

    Returns (vertices (V', 3) float32, faces (T, 3) int64, uv (V', 2) float32, texture (size, size, 3)
    uint8, coverage (size, size) bool). Faces keep the order of ``batch.triangles()``.
    """
    from mesh2tex.render import dilate_texture, unwrap_uv, uv_rasterize

    triangles = batch.shape_triangles(0).cpu()
    vertices = batch.shape_vertices(0).cpu()
    new_vertices, faces, uv, vertex_map = unwrap_uv(vertices, triangles)
    faces = torch.as_tensor(np.asarray(faces), dtype=torch.int64)
    vertex_map = torch.as_tensor(np.asarray(vertex_map), dtype=torch.int64)
    uv = torch.as_tensor(np.asarray(uv), dtype=torch.float32)
    if not torch.equal(vertex_map[faces], triangles):
        raise RuntimeError("unwrap_uv changed the face order or corners; baking needs them kept")
    device = texture.face_rgb.device
    raster = uv_rasterize(uv.to(device), faces.to(device), (size, size))
    covered = raster.face_id[0] >= 0
    colors = torch.zeros(size, size, 3, device=device)
    colors[covered] = field_colors(generator, texture, batch, raster.face_id[0][covered], raster.bary[0][covered]).float()
    image = dilate_texture(colors.permute(2, 0, 1), covered[None].float(), dilate)
    image = image.reshape(3, size, size)
    uint8 = ((image.clamp(-1, 1) + 1) * 127.5).round().to(torch.uint8).permute(1, 2, 0).cpu().numpy()
    return torch.as_tensor(np.asarray(new_vertices), dtype=torch.float32), faces, uv, uint8, covered.cpu()


@torch.no_grad()
def vertex_colors(generator: TextureGenerator, texture: FaceTexture, batch: MeshBatch) -> np.ndarray:
    """(V, 3) uint8 colours of shape 0's finest vertices: psi at each corner of each incident triangle, averaged."""
    triangles = batch.shape_triangles(0)
    t = triangles.shape[0]
    triangle_id = torch.arange(t, device=triangles.device).repeat_interleave(3) + 2 * int(batch.face_offsets[0][0])
    bary = torch.eye(3, device=triangles.device).repeat(t, 1)
    colors = field_colors(generator, texture, batch, triangle_id, bary).float()  # (3T, 3)
    v = batch.shape_vertices(0).shape[0]
    index = triangles.reshape(-1)
    summed = torch.zeros(v, 3, device=colors.device).index_add_(0, index, colors)
    counts = torch.zeros(v, device=colors.device).index_add_(0, index, torch.ones_like(index, dtype=torch.float32))
    mean = summed / counts.clamp(min=1).unsqueeze(1)
    return ((mean.clamp(-1, 1) + 1) * 127.5).round().to(torch.uint8).cpu().numpy()


def run(args) -> int:
    from mesh2tex.io.assets import save_glb, save_ply, smooth_vertex_normals

    device = select_device(args.device)
    seeds = parse_seeds(args.seeds)
    if args.views < 1 or args.resolution < 8 or args.texture_size < 16:
        raise UserError("--views must be >= 1, --resolution >= 8 and --texture-size >= 16")
    generator, meta = load_generator(args.checkpoint, device)
    camera = meta.get("config", {}).get("camera", {})
    distance, fov = float(camera.get("distance", 1.7)), float(camera.get("fov", 40.0))
    shape = load_shape(args.mesh, generator, args.faces)
    batch = collate_shapes([shape]).to(device)
    encoded = generator.encoder(batch)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    azimuth, elevation = sample_views(args.views, args.elevation)
    mvp = orbit_camera(azimuth, elevation, distance=distance, fov=fov).mvp.to(device)
    res = (args.resolution, args.resolution)
    white = torch.ones(args.views, 3, device=device)
    written = []
    with torch.no_grad():
        for seed in seeds:
            ws = latent(generator, seed, device, args.truncation)
            texture = generator.synthesize(batch, ws, encoded=encoded, noise_mode="none")
            views = render_field_views(generator, batch, ws, mvp, res, white, texture=texture)
            for v, image in enumerate(to_uint8(views.images)):
                save_png(out / f"seed{seed}_view{v}.png", image)
            verts, faces, uv, tex, _ = bake_texture(generator, texture, batch, args.texture_size)
            save_glb(out / f"seed{seed}.glb", verts.numpy(), faces.numpy(), uv.numpy(), tex, smooth_vertex_normals(verts.numpy(), faces.numpy()))
            save_ply(out / f"seed{seed}.ply", batch.shape_vertices(0).cpu().numpy(), batch.shape_triangles(0).cpu().numpy(),
                     vertex_colors(generator, texture, batch))
            written.append(seed)
            print(f"seed {seed}: {args.views} views, {out / f'seed{seed}.glb'}, {out / f'seed{seed}.ply'}")
    return 0
