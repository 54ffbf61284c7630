"""``mesh2tex infer synthesize``: texture the user's mesh after one exemplar image, no trained model.

    mesh2tex infer synthesize --exemplar IMG --mesh MESH --out DIR [--texture-size 512] [--iters 400]
                              [--direction-field up|smooth|none] [--direction-axis y|x|z]
                              [--method renders|surface|patches] [--loss patch|ps|sw|ot]
                              [--seed 0] [--device auto]
                              [--up auto|y|z] [--uv auto|keep|new] [--output-mesh input|prepared] [--overwrite]

The mesh's UV texture (its own UVs when usable, else a new xatlas atlas; ``--uv``) is optimised
directly, texel by texel through a coarse-to-fine pyramid, so that renders of the textured mesh from
random views (``--method renders``, the default) or geodesic charts walked on the surface itself
(``--method surface``, the paper's exponential-map neighbourhoods on a tangent direction field), or the
``patch`` loss's own patches walked on the surface octave by octave (``--method patches``), match
the exemplar's structure under a weight-free structure loss (:mod:`mesh2tex.texel_synthesis`).
``--direction-field up`` keeps every view or chart upright, so stripes keep one direction relative to
the mesh's up (``--direction-axis``: or its x or z); ``smooth`` (charts and patches) lays them along the
smoothest field that follows that axis on steep faces (:mod:`mesh2tex.geometry.direction_field`);
``none`` rolls them at random.

Writes into DIR: ``textured.glb`` (the user's own mesh, in its own frame and units, with the texture
in its UVs; opens in Blender), ``textured.ply`` (the same mesh with per-vertex colours),
``texture.png``, ``view_K.png`` renders and ``report.json`` (settings, timings, the loss before and
after, and the independent structure judge's scores of the views against the exemplar,
:func:`mesh2tex.metrics.structure.structure_scores`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import torch

from mesh2tex.config import load_config
from mesh2tex.errors import UserError
from mesh2tex.geometry.mesh_io import UserMesh
from mesh2tex.geometry.primitives import unit_transform
from mesh2tex.io.assets import check_texture_format
from mesh2tex.io.atomic import write_json
from mesh2tex.io.images import colours_to_uint8, images_to_uint8, load_image, save_png
from mesh2tex.io.outputs import guard_outputs
from mesh2tex.losses.ot_style import needs_vgg
from mesh2tex.metrics.structure import structure_scores
from mesh2tex.options import config_overrides
from mesh2tex.progress import progress_bar
from mesh2tex.render import orbit_camera
from mesh2tex.render.bake import BakedUserMesh, mesh_atlas
from mesh2tex.render.cameras import turntable_angles
from mesh2tex.runtime import select_device
from mesh2tex.texel_synthesis import (
    SynthesisConfig,
    TexelSurface,
    TexelSynthesis,
    exemplar_tensor,
    render_texture,
    vertex_texture_colours,
)
from mesh2tex.texturing import note, read_user_mesh, write_baked_mesh

OUTPUTS = ("textured.glb", "textured.ply", "texture.png", "report.json")
MIN_EXEMPLAR = 8  # an exemplar's shorter side, pixels, at least
METHOD_NAMES = {
    "renders": "texels optimised through rendered views",
    "surface": "texels optimised through geodesic charts of the surface (exponential map on the direction field)",
    "patches": "texels optimised through the patch loss's patches walked on the surface, octave by octave",
}


@dataclass
class InferSynthesizeConfig:
    views: int = 4  # renders written (view_K.png) and judged, around the mesh at 20 degrees elevation
    texture_format: str = "png"  # how the GLB embeds the texture: png (lossless), jpeg or webp (lossy, smaller)
    vgg_weights: str = ""  # VGG19 weights of the sw and ot losses ('': $TORCH_HOME, else random weights)
    device: str = "auto"  # auto, cpu or cuda
    synthesis: SynthesisConfig = field(default_factory=SynthesisConfig)  # the optimisation

    def __post_init__(self):
        if self.views < 1:
            raise UserError(f"--views must be at least 1, got {self.views}")
        check_texture_format(self.texture_format)


def build_config(args) -> InferSynthesizeConfig:
    """The config's defaults, then ``--config``, then the flags given."""
    return load_config(InferSynthesizeConfig, args.config, config_overrides(args))


def read_exemplar(path: str, size: int) -> torch.Tensor:
    """(1, 3, size, size) in [-1, 1]: the exemplar's centred square; a one-line error for a bad or tiny image."""
    rgb, _ = load_image(path)
    if min(rgb.shape[:2]) < MIN_EXEMPLAR:
        raise UserError(
            f"{path}: a {rgb.shape[1]}x{rgb.shape[0]} image is too small to be an exemplar "
            f"(at least {MIN_EXEMPLAR} px a side)"
        )
    return exemplar_tensor(rgb, size)


def atlas_surface(mesh: UserMesh, uv: str):
    """The atlas ``--uv`` gives the mesh and the surface the texture is optimised on: its vertices in the
    unit ball of its y-up working frame (split on the atlas's seams). Returns (atlas, surface, unit
    vertices (V, 3) of the mesh's own vertices)."""
    atlas = mesh_atlas(mesh, uv)
    working = mesh.working_vertices()
    unit = unit_transform(working, mesh.path).apply(working)
    return atlas, TexelSurface.from_arrays(unit[atlas.vertex_index], atlas.faces, atlas.uv), unit


def write_mesh(
    out, mesh: UserMesh, atlas, unit: np.ndarray, image: torch.Tensor, output_mesh: str, texture_format: str
) -> dict:
    """textured.glb and textured.ply: the user's mesh (``output_mesh`` input) or its unit-ball working copy
    (prepared), with the atlas's UVs and ``image`` (S, S, 3) in [-1, 1]; returns what the report says of it."""
    if output_mesh == "prepared":
        mesh = UserMesh(mesh.path, unit, mesh.faces, None, None, "y", "the working copy")
    colours = vertex_texture_colours(image, atlas.uv, atlas.vertex_index, len(mesh.vertices))
    normals = None if mesh.normals is None else mesh.normals[atlas.vertex_index]
    baked = BakedUserMesh(
        vertices=mesh.vertices[atlas.vertex_index],
        faces=atlas.faces,
        uv=atlas.uv,
        normals=normals,
        texture=colours_to_uint8(image),
        coverage=np.ones(image.shape[:2], dtype=bool),
        vertex_colours=colours_to_uint8(colours),
        atlas=atlas,
        surface_distance=np.zeros(len(mesh.vertices)),
    )
    written = write_baked_mesh(out / "textured.glb", out / "textured.ply", baked, mesh, texture_format)
    written.pop("surface_distance_max")  # the texture is on the mesh itself: no closest-point map
    return {**written, "mesh": output_mesh}


def optimise(synthesis: TexelSynthesis, iters: int) -> tuple[list[dict], float]:
    """``iters`` steps under a progress bar; returns (every tenth step's losses, seconds)."""
    log = []
    started = time.perf_counter()
    bar = progress_bar(range(iters), desc="infer synthesize")
    for step in bar:
        losses = synthesis.step()
        if step % 10 == 0 or step == iters - 1:
            log.append({"step": step + 1, **{k: round(v, 5) for k, v in losses.items()}})
            bar.set_postfix(loss=f"{losses['loss']:.3f}")
    return log, time.perf_counter() - started


def run(args) -> int:
    cfg = build_config(args)
    if args.output_mesh not in ("input", "prepared"):
        raise UserError(f"--output-mesh {args.output_mesh!r}: choose input or prepared")
    views = [f"view_{k}.png" for k in range(cfg.views)]
    out = guard_outputs(args.out, list(OUTPUTS) + views, args.overwrite)
    device = select_device(cfg.device)
    settings = cfg.synthesis
    exemplar = read_exemplar(args.exemplar, settings.exemplar_size)
    mesh = read_user_mesh(args.mesh, args.up)
    atlas, surface, unit = atlas_surface(mesh, args.uv)
    if atlas.note:
        note(f"{args.mesh}: a new UV atlas, as {atlas.note}")
    vgg = None
    if needs_vgg(settings.loss):
        from mesh2tex.nn.vgg import load_vgg19

        vgg = load_vgg19(cfg.vgg_weights or None, device=device)
    started = time.perf_counter()
    synthesis = TexelSynthesis(settings, surface, exemplar, vgg, device)
    initial = synthesis.fixed_loss()
    log, optimise_seconds = optimise(synthesis, settings.iters)
    final = synthesis.fixed_loss()
    image = synthesis.texture()
    out.mkdir(parents=True, exist_ok=True)
    save_png(out / "texture.png", colours_to_uint8(image))
    with torch.no_grad():
        angles = turntable_angles(cfg.views, 20.0, start=30.0)
        mvp = orbit_camera(*angles, distance=settings.camera.distance, fov=settings.camera.fov).mvp
        images, masks = render_texture(surface, image.permute(2, 0, 1), mvp, settings.resolution)
    for name, picture in zip(views, images_to_uint8(images)):
        save_png(out / name, picture)
    judge = structure_scores((images.double() + 1) / 2, masks.double(), (exemplar.double() + 1) / 2)
    exemplar_own = structure_scores((exemplar.double() + 1) / 2, None, (exemplar.double() + 1) / 2)
    written = write_mesh(out, mesh, atlas, unit, image, args.output_mesh, cfg.texture_format)
    report = {
        "exemplar": args.exemplar,
        "mesh": args.mesh,
        "config": _plain(cfg),
        "mip_level": synthesis.mip,
        "method": METHOD_NAMES[settings.method],
        "seconds": round(time.perf_counter() - started, 2),
        "optimise_seconds": round(optimise_seconds, 2),
        "ms_per_step": round(1000 * optimise_seconds / settings.iters, 2),
        "initial_loss": initial,
        "final_loss": final,
        "losses": log,
        "structure": judge.as_dict(),
        "exemplar_structure": exemplar_own.as_dict(),
        "output_mesh": written,
        "files": views + list(OUTPUTS),
    }
    write_json(out / "report.json", report)
    print(
        f"{settings.iters} steps ({report['ms_per_step']} ms each), {settings.loss} loss {initial:.3f} -> {final:.3f}, "
        f"judge SWD {judge.swd:.0f} (the exemplar against itself {exemplar_own.swd:.0f}): {out / 'textured.glb'}"
    )
    return 0


def _plain(cfg: InferSynthesizeConfig) -> dict:
    from mesh2tex.config import config_to_dict

    return config_to_dict(cfg)
