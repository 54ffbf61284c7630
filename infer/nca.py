"""``mesh2tex infer nca``: grow a trained cellular automaton's texture on any mesh.

    mesh2tex infer nca --checkpoint RUN/model.safetensors --mesh MESH --out DIR [--steps 96]
                       [--graft C2 --graft-mask EXPR|FILE] [--regrow EXPR] [--angle DEG]
                       [--subdivide auto|N] [--views 4] [--resolution 256] [--texture-size 1024]
                       [--frames 24] [--seed 0] [--device] [--overwrite]

Writes into DIR: ``view_K.png`` renders, ``textured.glb`` (the user's own mesh, in its own frame and
units, with the readout baked into its UVs or a new atlas; ``--up``, ``--uv``, ``--output-mesh`` as
in ``infer generate``; opens in Blender), ``textured.ply`` (the same mesh with per-vertex colours), ``growth.gif`` (the
texture growing from the seed, a quarter turn of the camera), ``state.safetensors`` (the final cell
states and positions) and ``report.json`` (settings, timings, the style loss of the renders against
the exemplar). ``--graft`` blends the updates, and the colour readouts, of a second model of the same lineage by
a mask on the mesh; ``--regrow`` zeroes the cells of a region after growth and grows them back (the frames
of the regrowth follow in the GIF).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from mesh2tex.config import load_config
from mesh2tex.errors import UserError, note
from mesh2tex.geometry.primitives import (
    density_subdivisions,
    mean_edge_length,
    read_surface,
    unit_surface,
    unit_transform,
)
from mesh2tex.geometry.regions import region_weights
from mesh2tex.io.assets import check_texture_format
from mesh2tex.io.atomic import atomic_path, write_json
from mesh2tex.io.checkpoint import save_checkpoint
from mesh2tex.io.images import images_to_uint8, save_png
from mesh2tex.io.outputs import guard_outputs
from mesh2tex.limits import check_range
from mesh2tex.losses.ot_style import ExemplarFeatures, style_loss
from mesh2tex.models import TrainedAutomaton, load_nca
from mesh2tex.nn.cell_graph import build_cell_graph
from mesh2tex.nn.render_texture import render_states
from mesh2tex.nn.vgg import load_vgg19
from mesh2tex.options import config_overrides
from mesh2tex.progress import progress_bar
from mesh2tex.render import orbit_camera
from mesh2tex.render.bake import BakeTarget
from mesh2tex.render.cameras import turntable_angles
from mesh2tex.runtime import select_device
from mesh2tex.texturing import read_user_mesh, source_mesh, write_automaton_mesh

OUTPUTS = ("textured.glb", "textured.ply", "growth.gif", "state.safetensors", "report.json")


@dataclass
class InferNCAConfig:
    steps: int = 96  # automaton steps from the seed
    angle: float = 0.0  # texture orientation: degrees about each vertex normal
    # split faces into four N times (0: the mesh as it is); auto: the count whose edges come nearest the training
    # mesh's
    subdivide: str = "auto"
    views: int = 4  # renders around the mesh
    resolution: int = 256  # render resolution
    texture_size: int = 1024  # side of the baked UV texture
    texture_format: str = "png"  # how the GLB embeds it: png (lossless), jpeg or webp (lossy, smaller)
    frames: int = 24  # frames of growth.gif (0: no GIF)
    seed: int = 0  # seed of the asynchronous updates
    # VGG19 weights for the report's style loss ('' looks in $TORCH_HOME, else a random-weight fallback)
    vgg_weights: str = ""
    device: str = "auto"  # auto, cpu or cuda

    def __post_init__(self):
        for name, low in (("steps", 1), ("views", 1), ("resolution", 32), ("texture_size", 16), ("frames", 0)):
            if getattr(self, name) < low:
                raise UserError(f"--{name.replace('_', '-')} must be at least {low}, got {getattr(self, name)}")
        # one turn either way is every orientation; far beyond, the float32 rotation turns to NaN
        self.angle = check_range("--angle", self.angle, -360.0, 360.0, "degrees")
        check_texture_format(self.texture_format)
        self.subdivide = str(self.subdivide)


def build_config(args) -> InferNCAConfig:
    """The config's defaults, then ``--config``, then the flags given."""
    return load_config(InferNCAConfig, args.config, config_overrides(args))


def choose_subdivisions(value: str, vertices: np.ndarray, faces: np.ndarray, cell_spacing: float) -> int:
    """--subdivide: a number, or "auto": the split count whose edges come nearest to the training mesh's
    (``cell_spacing``, the model's metadata; 0 for a model without it, which runs on the mesh as it is)."""
    if value != "auto":
        if not value.isdigit() or int(value) > 4:
            raise UserError(f"--subdivide {value}: expected auto or a number 0..4")
        return int(value)
    return density_subdivisions(mean_edge_length(vertices, faces), cell_spacing)


def read_cells_surface(
    spec: str, up: str, uv: str, output_mesh: str
) -> tuple[tuple[np.ndarray, np.ndarray], BakeTarget | None]:
    """The surface the cells grow on (vertices (V, 3) float64 y-up, faces) for ``--mesh spec``, and
    the user's mesh the texture is baked onto (None for the sphere, or ``--output-mesh prepared``):
    a mesh file itself, or the source mesh of a prepared shape (.npz) when it is found."""
    from mesh2tex.geometry.clean import Normalization
    from mesh2tex.geometry.mesh_io import is_mesh_file
    from mesh2tex.geometry.prepared import PreparedShape

    if not is_mesh_file(spec):
        surface = read_surface(spec)
        if output_mesh == "input" and spec.endswith(".npz"):
            shape = PreparedShape.load(spec)
            mesh = source_mesh(shape, spec, "the cell mesh")
            if mesh is not None:
                to_prepared = Normalization.from_json(shape.metadata["transform"])
                return surface, BakeTarget(mesh, to_prepared.then(unit_transform(surface[0], spec)), uv)
        return surface, None
    mesh = read_user_mesh(spec, up)
    surface = (mesh.working_vertices(), mesh.faces)
    if output_mesh == "prepared":
        return surface, None
    return surface, BakeTarget(mesh, unit_transform(surface[0], spec), uv)


def grow(model, graph, cfg: InferNCAConfig, graft, damage, distance: float, fov: float, device) -> tuple:
    """Grow the automaton from its seed for ``cfg.steps`` steps (and regrow the ``damage`` region as many
    again): (final state (1, V, C), the GIF's frames, seconds spent in steps, phases run). Frames are
    rendered along a quarter turn of the camera."""
    angle = math.radians(cfg.angle)
    generator = torch.Generator(device=device).manual_seed(cfg.seed)
    frames_at = set(np.linspace(0, cfg.steps, cfg.frames, dtype=int).tolist()) if cfg.frames else set()
    gif_size = min(cfg.resolution, 192)
    frames: list[np.ndarray] = []

    def frame(state, index, total):
        azimuth = 30.0 + 90.0 * index / max(total - 1, 1)
        mvp = orbit_camera(azimuth, 20.0, distance=distance, fov=fov).mvp.to(device)
        frames.append(
            images_to_uint8(render_states(model, state, graph, mvp, gif_size, background=1.0, graft=graft).images)[0]
        )

    state = model.seed_state(1, graph.num_cells, device, generator=torch.Generator().manual_seed(cfg.seed))
    total_frames = len(frames_at) * (2 if damage is not None else 1)
    step_seconds = 0.0
    with torch.no_grad():
        phases = [("grow", cfg.steps)] + ([("regrow", cfg.steps)] if damage is not None else [])
        for phase, steps in phases:
            if phase == "regrow":
                state = (
                    state.masked_fill(damage[None, :, None], 0.0)
                    if model.cfg.seed == "zero"
                    else torch.where(
                        damage[None, :, None],
                        model.seed_state(
                            1, graph.num_cells, device, generator=torch.Generator().manual_seed(cfg.seed + 1)
                        ),
                        state,
                    )
                )
            for step in progress_bar(range(steps + 1), desc=f"infer nca ({phase})"):
                if step in frames_at:
                    frame(state, len(frames), total_frames)
                if step == steps:
                    break
                tick = time.perf_counter()
                state = model.step(state, graph, angle=angle, graft=graft, generator=generator)
                step_seconds += time.perf_counter() - tick
    return state, frames, step_seconds, len(phases)


def exemplar_style(views, exemplar: np.ndarray, depth: int, cfg: InferNCAConfig, device) -> float:
    """The style loss of the final renders against the model's exemplar (H, W, 3) uint8, with the training's VGG
    depth."""
    vgg = load_vgg19(cfg.vgg_weights or None, device=device, warn=False)
    target = torch.from_numpy(exemplar).permute(2, 0, 1)[None].float().to(device) / 127.5 - 1
    return float(
        style_loss(
            vgg,
            views.images,
            views.mask,
            ExemplarFeatures.compute(vgg, target, depth),
            generator=torch.Generator().manual_seed(0),
        )
    )


def write_gif(path: Path, frames: list[np.ndarray]) -> None:
    """The frames as an animated GIF (10 frames a second, looping), written atomically."""
    from PIL import Image

    pictures = [Image.fromarray(f) for f in frames]
    with atomic_path(path) as tmp:
        pictures[0].save(tmp, format="GIF", save_all=True, append_images=pictures[1:], duration=100, loop=0)


def run(args) -> int:
    cfg = build_config(args)
    out = guard_outputs(args.out, list(OUTPUTS) + [f"view_{k}.png" for k in range(cfg.views)], args.overwrite)
    device = select_device(cfg.device)
    trained = load_nca(args.checkpoint, device)
    model, exemplar = trained.network, trained.exemplar
    distance, fov = trained.camera.distance, trained.camera.fov  # frame the unit ball as training did
    other, lineage_note = _graft_model(args, trained, device)
    # read once, subdivided from these arrays
    surface, bake_target = read_cells_surface(args.mesh, args.up, args.uv, args.output_mesh)
    graph, subdivisions, edge_ratio = _cells(surface, args.mesh, cfg.subdivide, trained, device)
    graft, damage = _regions(args, graph, other, device)
    out.mkdir(parents=True, exist_ok=True)

    started = time.perf_counter()
    with torch.no_grad():
        state, frames, step_seconds, phases = grow(model, graph, cfg, graft, damage, distance, fov, device)
        if not torch.isfinite(state).all():
            raise UserError(
                f"{args.checkpoint}: the automaton's states became non-finite on {args.mesh}; try fewer --steps"
            )

        mvp = orbit_camera(*turntable_angles(cfg.views, 20.0, start=30.0), distance=distance, fov=fov).mvp.to(device)
        views = render_states(model, state, graph, mvp, cfg.resolution, background=1.0, graft=graft)
        for k, image in enumerate(images_to_uint8(views.images)):
            save_png(out / f"view_{k}.png", image)
        style = None if exemplar is None else exemplar_style(views, exemplar, trained.vgg_depth, cfg, device)

        written = write_automaton_mesh(
            out / "textured.glb",
            out / "textured.ply",
            model,
            state,
            graph,
            cfg.texture_size,
            cfg.texture_format,
            graft=graft,
            target=bake_target,
        )
    if written.get("uv_note"):
        note(f"{args.mesh}: a new UV atlas, as {written['uv_note']}")
    save_checkpoint(
        out / "state.safetensors",
        {"cells": {"state": state[0].cpu(), "positions": graph.positions.cpu()}},
        kind="nca_state",
        meta={"checkpoint": str(args.checkpoint), "mesh": args.mesh, "steps": cfg.steps},
    )
    if frames:
        write_gif(out / "growth.gif", frames)
    report = {
        "checkpoint": str(args.checkpoint),
        "mesh": args.mesh,
        "cells": graph.num_cells,
        "subdivisions": subdivisions,
        "edge_ratio": None if edge_ratio is None else round(edge_ratio, 3),
        "steps": cfg.steps,
        "regrow": args.regrow,
        "graft": args.graft,
        "graft_mask": args.graft_mask if args.graft else None,
        "lineage": lineage_note,
        "angle_degrees": cfg.angle,
        "seconds": round(time.perf_counter() - started, 2),
        "ms_per_step": round(1000 * step_seconds / (cfg.steps * phases), 3),
        "style_loss": style,
        "output_mesh": written,
        "files": [f"view_{k}.png" for k in range(cfg.views)] + [n for n in OUTPUTS if (out / n).exists()],
    }
    write_json(out / "report.json", report)
    print(_summary(report, out, cfg.steps, edge_ratio))
    if lineage_note:
        print(f"mesh2tex: note: {lineage_note}")
    return 0


def _summary(report: dict, out: Path, steps: int, edge_ratio: float | None) -> str:
    """The line that closes a run: cells, density (``edge_ratio`` unrounded), steps and their cost, the asset
    and the style loss."""
    subdivisions, style = report["subdivisions"], report["style_loss"]
    density = f"faces split into four {subdivisions}x" if subdivisions else "the mesh as it is"
    if edge_ratio is None:
        density += "; the model records no training cell spacing"
    else:
        density += f", edges {edge_ratio:.2f}x the training mesh's"
    line = (
        f"{report['cells']} cells ({density}), {steps} steps ({report['ms_per_step']} ms each): {out / 'textured.glb'}"
    )
    return line + (f"; style loss {style:.3f}" if style is not None else "")


def _graft_model(args, trained: TrainedAutomaton, device: torch.device) -> tuple[object | None, str | None]:
    """The automaton of ``--graft`` (None without it) and the note when it is not of the checkpoint's lineage."""
    if not args.graft:
        return None, None
    grafted = load_nca(args.graft, device)
    if grafted.network.cfg != trained.network.cfg:
        raise UserError(
            f"{args.graft}: its automaton config differs from {args.checkpoint}'s; only models of one lineage can be "
            "grafted"
        )
    return grafted.network, lineage(trained, grafted)


def _cells(surface, mesh: str, subdivide, trained: TrainedAutomaton, device: torch.device):
    """The cell graph of the user's surface in the unit ball, its faces split into four as often as
    ``subdivide`` asks (or as the training cell spacing needs): (graph, subdivisions, edge length over the
    training mesh's, None when the model records no spacing)."""
    vertices, faces = unit_surface(*surface, name=mesh)
    cell_spacing = trained.cell_spacing
    subdivisions = choose_subdivisions(subdivide, vertices, faces, cell_spacing)
    if subdivisions:
        vertices, faces = unit_surface(*surface, subdivide=subdivisions, name=mesh)
    edge_ratio = mean_edge_length(vertices, faces) / cell_spacing if cell_spacing > 0 else None
    return build_cell_graph(vertices, faces, trained.network.cfg.neighbourhood).to(device), subdivisions, edge_ratio


def _regions(args, graph, other, device: torch.device) -> tuple[tuple | None, torch.Tensor | None]:
    """(the graft: (other automaton, per-cell weights (N,)) or None, the cells ``--regrow`` damages (N,) bool or
    None)."""
    positions = graph.positions.cpu().numpy()
    graft = None if other is None else (other, torch.from_numpy(region_weights(args.graft_mask, positions)).to(device))
    damage = None
    if args.regrow:
        damage = torch.from_numpy(region_weights(args.regrow, positions) > 0.5).to(device)
        if not bool(damage.any()):
            raise UserError(f"--regrow {args.regrow}: the region holds no vertex of this mesh")
    return graft, damage


def lineage(first: TrainedAutomaton, second: TrainedAutomaton) -> str | None:
    """None when two models are of one lineage (one trained from the other, or both from one ancestor), else a
    warning."""
    if first.lineage and first.lineage == second.lineage:
        return None
    return "the two models are not of one lineage (train the second with --parent FIRST); the graft may not blend"
