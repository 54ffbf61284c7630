"""``mesh2tex infer generate``: texture a mesh from random latent codes with a trained GAN.

    mesh2tex infer generate --checkpoint RUN/checkpoint.safetensors --mesh MESH_OR_NPZ --out DIR
                            [--seeds 0,1,2] [--views 8] [--resolution 512] [--texture-size 1024]
                            [--texture-format png|jpeg|webp] [--overwrite]

``--config YAML`` sets any field of :class:`GenerateConfig` (the flags override it).

Writes, per seed S: ``seed{S}_view{V}.png`` (orbit views, azimuths evenly spaced), ``seed{S}.glb``
and ``seed{S}.ply``: the user's own mesh (its vertices, faces, frame and units; ``--up`` says which
axis is up) with a UV texture baked from psi into its own UVs when usable, else a new atlas
(``--uv``), and with the colour at each vertex (:mod:`mesh2tex.render.bake`). A raw mesh is prepared
on the fly with the hierarchy the model was trained on (``--faces`` overrides it); a prepared shape
(.npz) brings its source mesh's path. ``--output-mesh prepared`` writes the prepared working copy
instead (normalised frame: bounding-box centre at the origin, diagonal 1). Files already in DIR are
never replaced without ``--overwrite``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch

from mesh2tex.config import load_config
from mesh2tex.errors import UserError, note
from mesh2tex.io.assets import check_texture_format
from mesh2tex.io.images import images_to_uint8, save_png
from mesh2tex.io.outputs import guard_outputs
from mesh2tex.models import load_generator
from mesh2tex.nn.batch import collate_shapes
from mesh2tex.nn.render_texture import render_field_views
from mesh2tex.options import config_overrides, parse_seeds  # --seeds: lists and ranges (0-7, 0,2,5-9)
from mesh2tex.progress import progress_bar, write_line
from mesh2tex.render import orbit_camera, turntable_angles
from mesh2tex.runtime import select_device
from mesh2tex.texturing import TexturedMeshWriter, latent, load_shape


@dataclass
class GenerateConfig:
    seeds: list[int] = field(default_factory=lambda: [0, 1, 2])  # latent seeds, one texture each
    views: int = 8  # orbit views per seed, azimuths evenly spaced
    resolution: int = 512  # side of the rendered views
    texture_size: int = 1024  # side of the UV texture baked into each GLB
    texture_format: str = "png"  # how the GLB embeds it: png (lossless), jpeg or webp (lossy, smaller)
    elevation: float = 20.0  # elevation of the orbit views, degrees
    truncation: float = 1.0  # truncation psi of the latent (1: none)
    # finest quad count when a raw mesh is prepared on the fly (0: the hierarchy the model was trained on)
    faces: int = 0
    device: str = "auto"  # auto, cpu or cuda

    def __post_init__(self):
        if not self.seeds:
            raise UserError("--seeds: give at least one seed")
        if self.views < 1 or self.resolution < 8 or self.texture_size < 16:
            raise UserError("--views must be >= 1, --resolution >= 8 and --texture-size >= 16")
        check_texture_format(self.texture_format)


def output_names(cfg: GenerateConfig) -> list[str]:
    """The files the command writes into --out."""
    return [
        name
        for seed in cfg.seeds
        for name in [f"seed{seed}_view{v}.png" for v in range(cfg.views)] + [f"seed{seed}.glb", f"seed{seed}.ply"]
    ]


def build_config(args) -> GenerateConfig:
    """The config's defaults, then ``--config``, then the flags given."""
    return load_config(
        GenerateConfig,
        args.config,
        config_overrides(args, computed={"seeds": None if args.seeds is None else parse_seeds(args.seeds)}),
    )


def run(args) -> int:
    cfg = build_config(args)
    device = select_device(cfg.device)
    model = load_generator(args.checkpoint, device)
    generator, distance, fov = model.network, model.camera.distance, model.camera.fov
    shape, target = load_shape(
        args.mesh, generator, model.face_count(cfg.faces), up=args.up, uv=args.uv, output_mesh=args.output_mesh
    )
    batch = collate_shapes([shape]).to(device)
    encoded = generator.encoder(batch)
    # after the inputs are checked, before anything is written
    out = guard_outputs(args.out, output_names(cfg), args.overwrite)
    writer = TexturedMeshWriter(generator, batch, target, cfg.texture_size, cfg.texture_format)
    if writer.uv_note:
        note(f"{args.mesh}: a new UV atlas, as {writer.uv_note}")
    out.mkdir(parents=True, exist_ok=True)
    azimuth, elevation = turntable_angles(cfg.views, cfg.elevation)
    mvp = orbit_camera(azimuth, elevation, distance=distance, fov=fov).mvp.to(device)
    res = (cfg.resolution, cfg.resolution)
    white = torch.ones(cfg.views, 3, device=device)
    with torch.no_grad():
        for seed in progress_bar(cfg.seeds, desc="infer generate", unit="seed"):
            ws = latent(generator, seed, device, cfg.truncation)
            texture = generator.synthesize(batch, ws, encoded=encoded, noise_mode="none")
            views = render_field_views(generator, batch, ws, mvp, res, white, texture=texture)
            if not bool(torch.isfinite(views.images).all()):  # would be written as black pixels without a word
                raise UserError(
                    f"{args.checkpoint}: the generator's colours for seed {seed} are not finite (damaged weights?)"
                )
            for v, image in enumerate(images_to_uint8(views.images)):
                save_png(out / f"seed{seed}_view{v}.png", image)
            written = writer.write(out / f"seed{seed}.glb", out / f"seed{seed}.ply", texture)
            write_line(
                f"seed {seed}: {cfg.views} views, {out / f'seed{seed}.glb'}, {out / f'seed{seed}.ply'} "
                f"({written['mesh']} mesh, {written['triangles']} triangles)"
            )
    return 0
