"""Does an automaton trained with a given style loss reproduce its exemplar's *structure*?

    OMP_NUM_THREADS=1 python benchmarks/nca_structure.py [--exemplars stripes checker ...] [--losses ot sw ps]
        [--iters 150] [--seed 0] [--meshes CHAIR.npz ...] [--runs DIR] [--out FILE.json]
        [--direct ps sw ...] [--surface ps ...] [--patches] [--direct-iters 400] [--direct-size 512]
        [--charts 16 --chart-size 32] [--patch-reuse 1]
        [--figure FILE.png [--figure-view 1]]

For each exemplar (a name of :data:`mesh2tex.synthetic.exemplars.EXEMPLARS`, drawn at 128 px over
the unit square) and each loss, an automaton of the default config is trained from scratch on the
sphere (``train nca``'s loop and defaults, only ``--iters`` and ``style_loss`` changed), grown 60
steps from its seed and rendered from 8 fixed views at 128 px (azimuths 0..315, elevations +-15)
on the sphere and on each ``--meshes`` file (held out: never trained on). Each set of renders is
judged by :mod:`mesh2tex.metrics.structure`, which shares nothing with the losses: SWD of raw
Laplacian-pyramid patches against the exemplar (x1000, lower is better), the windows' gradient
coherence (stripes: 1) and perpendicular energy ratio (checks: near 1), the spectral period
in pixels and the regularity (the autocorrelation's strongest repeat: periodic patterns near 1,
blotches near 0; the exemplar's own figures are printed in its header). The exemplar SWD compares renders
of a curved surface with a flat image, and the oracle (the pattern projected on the surface) does
not always win it; so beside it, ``vs oracle``: the same patch SWD against the oracle's own renders
with its pattern moved (:data:`REFERENCE_SHIFT`; same views, ``turns`` off): the ground truth as the
surface shows it, which the oracle row, its structure in another place, should win. And ``ps vs
oracle``: the oriented-band statistics of each render (the ``ps`` loss's, :func:`ps_vs_oracle`) against
the same moved oracle's render of that view: the judge of rows trained with the ``patch`` loss, whose raw
patches are too near the SWD's to judge them. Both compare directions as well as structure: the oracle's
pattern is solid (its stripes are the level sets of one 3D direction, so each view shows them at its own
angle), where ``infer synthesize``'s direction field ``up`` lays the exemplar at one angle to the mesh's up. So
``vs field`` and ``ps vs field`` are the same two distances against the *field oracle* moved
(:func:`oracle_views` with ``field``: the exemplar laid in each view's image plane, as the field lays it), and the
field oracle is a row.

Rows: ``oracle`` (the exemplar's pattern painted per pixel at the exemplar's pixel scale),
``vertex oracle`` (the pattern at the vertices, through a linear readout: what the cells can hold),
``flat`` (the exemplar's mean colour), ``vertex noise`` (each vertex a random exemplar pixel's
colour), then one row per loss (``ot`` is today's default), then with ``--direct`` one row per loss of
the direct method (``direct LOSS``: ``infer synthesize``'s texels optimised through renders,
:mod:`mesh2tex.texel_synthesis`, on a new xatlas atlas of each mesh with its defaults but the loss,
``--direct-iters`` and ``--direct-size``; run on each mesh, since it needs no training), and with
``--surface`` the same through geodesic charts of the surface in place of renders (``surface LOSS``:
``infer synthesize --method surface``), and with ``--patches`` the ``patch`` loss's patches walked on
the surface octave by octave (``patches patch``: ``infer synthesize --method patches``; with
``--patch-fields up smooth`` a row per direction field, ``patches smooth`` for ``--direction-field smooth``).
Summary per loss: its SWD over the
oracle's and over ``ot``'s, on each mesh. One thread; with ``--runs`` the trained models are saved
there (``<exemplar>_<loss>.safetensors``) and reused when present. With ``--figure`` one picture
is written: a row per exemplar (the exemplar, then on each mesh the oracle and the field oracle, each loss's automaton
and each direct row, seen from ``--figure-view``, one of the 8 judged views).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mesh2tex.train import runs  # noqa: E402

from benchmarks.nca_quality import RESOLUTION, STEPS, Judge, colour_model, grow, view_angles, views_mvp  # noqa: E402
from mesh2tex.geometry.primitives import load_surface  # noqa: E402
from mesh2tex.losses.ot_style import needs_vgg  # noqa: E402
from mesh2tex.losses.structure import band_statistics, statistics_distance  # noqa: E402
from mesh2tex.metrics.structure import patch_swd, structure_scores  # noqa: E402
from mesh2tex.models import load_nca  # noqa: E402
from mesh2tex.nn.cell_graph import build_cell_graph  # noqa: E402
from mesh2tex.nn.render_texture import render_states  # noqa: E402
from mesh2tex.nn.vgg import load_vgg19  # noqa: E402
from mesh2tex.render import interpolate, orbit_direction, rasterize, transform_points  # noqa: E402
from mesh2tex.render.bake import new_atlas  # noqa: E402
from mesh2tex.synthetic.exemplars import EXEMPLARS, exemplar_image  # noqa: E402
from mesh2tex.texel_synthesis import (  # noqa: E402
    DIRECTIONS,
    SynthesisConfig,
    TexelSurface,
    TexelSynthesis,
    render_texture,
)
from train.nca import NCATrainer, TrainNCAConfig  # noqa: E402

SIZE = 128  # exemplar pixels over the unit square of its pattern


def train_model(exemplar: torch.Tensor, loss: str, iters: int, seed: int, graph, vgg, save: Path | None):
    """An automaton trained ``iters`` iterations of ``train nca``'s loop with the style loss ``loss``
    (a name of STYLE_LOSSES; NAME@METHOD: with ``method`` METHOD, e.g. ``patch@patches``; then +colourW:
    with ``colour_weight`` W, e.g. ``patch@patches+colour1``)."""
    timing = save.with_suffix(".json") if save is not None else None
    if save is not None and save.is_file():
        model, _, _ = load_nca(save)
        return model, json.loads(timing.read_text())["train_seconds"] if timing.is_file() else math.nan
    name, _, weight = loss.partition("+colour")
    name, _, method = name.partition("@")
    cfg = TrainNCAConfig(
        seed=seed, iters=iters, style_loss=name, colour_weight=float(weight or 0), method=method or "renders"
    )
    with tempfile.TemporaryDirectory() as tmp:
        trainer = NCATrainer(cfg, exemplar, graph, runs.RunDirectory(tmp), torch.device("cpu"), vgg)
        start = time.perf_counter()
        while trainer.iteration < iters:
            trainer.step()
        seconds = time.perf_counter() - start
        if save is not None:
            trainer.save_model(save)
            timing.write_text(json.dumps({"train_seconds": seconds, "iters": iters, "loss": loss, "seed": seed}))
    return trainer.model.eval(), seconds


# Where the oracle-relative judge's reference puts the pattern: the oracle's own pattern moved by this much
# (pattern units; the patterns' periods are 1 or less), so that the oracle row is compared with its structure in
# another place, not with itself.
REFERENCE_SHIFT = (0.37, 0.61, 0.23)


@torch.no_grad()
def oracle_views(
    name: str, graph, mvp: torch.Tensor, shift=(0.0, 0.0, 0.0), field: bool = False
) -> tuple[torch.Tensor, torch.Tensor]:
    """The exemplar's pattern painted per pixel on the mesh at the exemplar's pixel scale (moved by ``shift``
    pattern units): images (N, 3, H, W) in [0, 1] (background 1), masks (N, 1, H, W).

    ``field``: the *field oracle*, the exemplar laid as the direction field ``up`` lays it: in each of the N
    judged views (:func:`view_angles`, ``mvp`` their matrices) the pattern's x and y are the camera's right and
    up, so its stripes keep one angle to the mesh's up wherever the surface faces the camera. It is a
    reference, not a texture: each view projects the pattern afresh."""
    raster = rasterize(transform_points(graph.positions, mvp), graph.triangles, (RESOLUTION, RESOLUTION))
    points = interpolate(graph.positions, raster, graph.triangles).double()  # (N, H, W, 3)
    normals = torch.nn.functional.normalize(interpolate(graph.normals, raster, graph.triangles), dim=-1).double()
    if field:
        forward = -orbit_direction(*view_angles(mvp.shape[0])).double()  # (N, 3) camera -> origin
        world_up = torch.tensor([0.0, 1.0, 0.0], dtype=forward.dtype).expand_as(forward)
        right = torch.nn.functional.normalize(torch.linalg.cross(forward, world_up), dim=-1)
        up = torch.linalg.cross(right, forward)
        across, along = (torch.einsum("nhwc,nc->nhw", points, axis) for axis in (right, up))
        points = torch.stack([across, along, torch.zeros_like(across)], -1)
        normals = torch.tensor([0.0, 0.0, 1.0], dtype=points.dtype).expand_as(points)  # as exemplar_image's square
    mask = raster.face_id >= 0
    pattern = points[mask].numpy() * Judge.pattern_scale(SIZE) + np.asarray(shift)
    rgb = EXEMPLARS[name](pattern, normals[mask].numpy())
    images = torch.ones(mvp.shape[0], RESOLUTION, RESOLUTION, 3, dtype=torch.float64)
    images[mask] = torch.from_numpy(rgb)
    return images.permute(0, 3, 1, 2), mask[:, None].double()


@torch.no_grad()
def state_views(model, state, graph, mvp) -> tuple[torch.Tensor, torch.Tensor]:
    views = render_states(model, state, graph, mvp, RESOLUTION, background=1.0)
    return ((views.images.double().clamp(-1, 1) + 1) / 2), views.mask.double()


def direct_views(
    exemplar: torch.Tensor,
    loss: str,
    graph,
    mvp: torch.Tensor,
    vgg,
    iters: int,
    size: int,
    seed: int,
    method: str = "renders",
    charts: int = SynthesisConfig.charts,
    chart_size: int = SynthesisConfig.chart_size,
    patch_reuse: int = SynthesisConfig.patch_reuse,
    direction_field: str = "up",
) -> tuple[tuple[torch.Tensor, torch.Tensor], float]:
    """The direct method's texture on ``graph``'s mesh (a new atlas over its triangles), optimised ``iters``
    steps with the ``loss`` through ``method`` (renders or surface charts) along ``direction_field``, seen by
    ``mvp``: ((images (N, 3, H, W) in [0, 1], masks), seconds)."""
    vertex_index, faces, uv = new_atlas(graph.positions.double().numpy(), graph.triangles.numpy())
    surface = TexelSurface.from_arrays(graph.positions.numpy()[vertex_index], faces, uv)
    cfg = SynthesisConfig(
        iters=iters,
        texture_size=size,
        loss=loss,
        exemplar_size=SIZE,
        resolution=RESOLUTION,
        seed=seed,
        method=method,
        charts=charts,
        chart_size=chart_size,
        patch_reuse=patch_reuse,
        direction_field=direction_field,
    )
    synthesis = TexelSynthesis(cfg, surface, exemplar, vgg if needs_vgg(loss) else None)
    start = time.perf_counter()
    for _ in range(iters):
        synthesis.step()
    seconds = time.perf_counter() - start
    with torch.no_grad():
        images, masks = render_texture(surface, synthesis.texture().permute(2, 0, 1), mvp, RESOLUTION)
    return ((images.double() + 1) / 2, masks.double()), seconds


@torch.no_grad()
def view_statistics(images: torch.Tensor, masks: torch.Tensor) -> list[dict[str, torch.Tensor]]:
    """The ``ps`` loss's statistics of each of N views, images (N, 3, H, W) in [0, 1] and masks (N, 1, H, W)."""
    return [band_statistics(images[n : n + 1].float() * 2 - 1, masks[n : n + 1].float()) for n in range(len(images))]


@torch.no_grad()
def ps_vs_oracle(images: torch.Tensor, masks: torch.Tensor, reference: list[dict[str, torch.Tensor]]) -> float:
    """The mean over the N views (images (N, 3, H, W) in [0, 1], masks (N, 1, H, W)) of the ``ps`` statistics'
    distance of a render to the reference's statistics of the same view (:func:`view_statistics`); NaN where
    no reference view has statistics."""
    values = [
        float(statistics_distance(mine, theirs))
        for mine, theirs in zip(view_statistics(images, masks), reference)
        if theirs
    ]
    return sum(values) / len(values) if values else math.nan


def fmt(value: float, digits: int = 2) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--exemplars", nargs="+", default=["stripes", "checker", "bricks", "dots", "brick", "grass", "gravel"]
    )
    parser.add_argument(
        "--losses",
        nargs="*",
        default=["ot", "sw", "ps"],
        help="automaton rows by style loss, NAME@METHOD with train nca's method (patch@patches), then +colourW "
        "with colour_weight W (patch+colour1); "
        "none: only the oracle and baseline rows",
    )
    parser.add_argument(
        "--iters", type=int, default=150, help="training iterations per model (train nca's default is 1500)"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--meshes", nargs="*", default=[], help="held-out meshes (prepared .npz or mesh files)")
    parser.add_argument("--runs", help="folder to keep (and reuse) the trained models")
    parser.add_argument("--out", help="write every figure as JSON here")
    parser.add_argument(
        "--direct", nargs="*", default=[], help="losses of direct-method rows (infer synthesize), e.g. ps sw"
    )
    parser.add_argument(
        "--surface", nargs="*", default=[], help="losses of direct-method rows through geodesic charts, e.g. ps"
    )
    parser.add_argument(
        "--patches", action="store_true", help="a direct-method row of the patch loss's patches walked on the surface"
    )
    parser.add_argument(
        "--patch-fields",
        nargs="+",
        default=["up"],
        choices=DIRECTIONS,
        help="with --patches: one row per direction field (patches patch for up, patches FIELD for the others)",
    )
    parser.add_argument("--direct-iters", type=int, default=SynthesisConfig.iters, help="the direct method's steps")
    parser.add_argument(
        "--direct-size", type=int, default=SynthesisConfig.texture_size, help="the direct method's texture side"
    )
    parser.add_argument("--charts", type=int, default=SynthesisConfig.charts, help="the chart rows' charts per step")
    parser.add_argument(
        "--chart-size", type=int, default=SynthesisConfig.chart_size, help="the chart rows' chart side in px"
    )
    parser.add_argument(
        "--patch-reuse", type=int, default=SynthesisConfig.patch_reuse, help="the patches row's synthesis.patch_reuse"
    )
    parser.add_argument("--figure", help="write a picture of every exemplar's rows here (PNG)")
    parser.add_argument(
        "--figure-view", type=int, default=1, choices=range(8), help="which judged view the picture shows"
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    unknown = [n for n in args.exemplars if n not in EXEMPLARS]
    if unknown:
        parser.error(f"unknown exemplars {unknown}; choose from {sorted(EXEMPLARS)}")
    vgg = load_vgg19(None, warn=False)
    cfg = TrainNCAConfig()
    meshes = {"sphere": cfg.mesh, **{Path(m).stem: m for m in args.meshes}}
    graphs = {key: build_cell_graph(*load_surface(spec), cfg.nca.neighbourhood) for key, spec in meshes.items()}
    mvp = views_mvp()
    runs_dir = Path(args.runs) if args.runs else None
    if runs_dir is not None:
        runs_dir.mkdir(parents=True, exist_ok=True)
    results: dict = {"iters": args.iters, "seed": args.seed, "meshes": meshes, "exemplars": {}}
    direct_rows = [(f"direct {loss}", loss, "renders", "up") for loss in args.direct]
    direct_rows += [(f"surface {loss}", loss, "surface", "up") for loss in args.surface]
    for field in args.patch_fields if args.patches else []:
        direct_rows.append(("patches patch" if field == "up" else f"patches {field}", "patch", "patches", field))
    shown = ["oracle", "field oracle", *args.losses, *(row[0] for row in direct_rows)]
    figure_rows: list[tuple[str, list[torch.Tensor]]] = []
    for name in args.exemplars:
        image = exemplar_image(name, SIZE)
        target = torch.from_numpy(image).permute(2, 0, 1)[None].double() / 255
        own = structure_scores(target, None, target)
        record: dict = {"exemplar": own.as_dict(), "rows": {}, "train_seconds": {}}
        pixels = torch.from_numpy(image.reshape(-1, 3)).float() / 127.5 - 1
        tiles = [torch.nn.functional.interpolate(target, size=(RESOLUTION, RESOLUTION), mode="area")[0]]
        models = {}
        for loss in args.losses:
            save = runs_dir / f"{name}_{loss}.safetensors" if runs_dir else None
            models[loss], record["train_seconds"][loss] = train_model(
                target.float() * 2 - 1, loss, args.iters, args.seed, graphs["sphere"], vgg, save
            )
        for mesh, graph in graphs.items():
            sets = {"oracle": oracle_views(name, graph, mvp)}
            sets["field oracle"] = oracle_views(name, graph, mvp, field=True)
            vertex_rgb = (
                torch.from_numpy(
                    EXEMPLARS[name](
                        graph.positions.double().numpy() * Judge.pattern_scale(SIZE), graph.normals.double().numpy()
                    )
                ).float()
                * 2
                - 1
            )
            baselines = {
                "vertex oracle": colour_model(vertex_rgb),
                "flat": colour_model(pixels.mean(0).expand(graph.num_cells, 3).clone()),
                "vertex noise": colour_model(
                    pixels[
                        torch.randint(pixels.shape[0], (graph.num_cells,), generator=torch.Generator().manual_seed(0))
                    ]
                ),
            }
            for row, (model, state) in baselines.items():
                sets[row] = state_views(model, state, graph, mvp)
            for loss, model in models.items():
                sets[loss] = state_views(model, grow(model, graph, STEPS, seed=args.seed), graph, mvp)
            for row, loss, method, field in direct_rows:
                sets[row], seconds = direct_views(
                    target.float() * 2 - 1,
                    loss,
                    graph,
                    mvp,
                    vgg,
                    args.direct_iters,
                    args.direct_size,
                    args.seed,
                    method,
                    args.charts,
                    args.chart_size,
                    args.patch_reuse,
                    field,
                )
                record["train_seconds"][f"{row} ({mesh})"] = seconds
            reference = oracle_views(name, graph, mvp, REFERENCE_SHIFT)
            reference_statistics = view_statistics(*reference)  # once per mesh, for every row
            field = oracle_views(name, graph, mvp, REFERENCE_SHIFT, field=True)
            field_statistics = view_statistics(*field)
            for row, (images, masks) in sets.items():
                scores = structure_scores(images, masks, target).as_dict()
                scores["oracle_swd"] = patch_swd(images, masks, reference[0], turns=False, exemplar_masks=reference[1])
                scores["oracle_ps"] = ps_vs_oracle(images, masks, reference_statistics)
                scores["field_swd"] = patch_swd(images, masks, field[0], turns=False, exemplar_masks=field[1])
                scores["field_ps"] = ps_vs_oracle(images, masks, field_statistics)
                record["rows"].setdefault(row, {})[mesh] = scores
            tiles += [sets[row][0][args.figure_view] for row in shown]
        results["exemplars"][name] = record
        figure_rows.append((name, tiles))
        if args.figure:
            write_figure(
                Path(args.figure), figure_rows, ["exemplar"] + [f"{m}: {row}" for m in graphs for row in shown]
            )
        print_exemplar(name, record, list(graphs), args.losses + [row[0] for row in direct_rows])
        if args.out:
            Path(args.out).write_text(json.dumps(results, indent=1))
    return 0


def write_figure(path: Path, rows: list[tuple[str, list[torch.Tensor]]], columns: list[str]) -> None:
    """A grid of square tiles ((3, S, S) in [0, 1], all one size), one row per exemplar, the ``columns`` named
    above them."""
    from PIL import Image, ImageDraw

    side, label = rows[0][1][0].shape[-1], 14
    image = Image.new("RGB", (side * len(columns), label + (side + label) * len(rows)), "white")
    draw = ImageDraw.Draw(image)
    for c, title in enumerate(columns):
        draw.text((c * side + 3, 1), title, fill="black")
    for r, (name, tiles) in enumerate(rows):
        top = label + r * (side + label)
        draw.text((3, top + 1), name, fill="black")
        for c, tile in enumerate(tiles):
            pixels = (tile.clamp(0, 1).permute(1, 2, 0).numpy() * 255 + 0.5).astype("uint8")
            image.paste(Image.fromarray(pixels), (c * side, top + label))
    path.parent.mkdir(parents=True, exist_ok=True)
    image.save(path)


def print_exemplar(name: str, record: dict, meshes: list[str], losses: list[str]) -> None:
    own = record["exemplar"]
    print(
        f"\n{name}: exemplar coherence {fmt(own['coherence'])}, ratio {fmt(own['ratio'])}, period "
        f"{fmt(own['period'], 1)} px, regularity {fmt(own['regularity'])}, self-SWD {fmt(own['swd'], 0)}; train s: "
        + ", ".join(f"{k} {fmt(v, 0)}" for k, v in record["train_seconds"].items())
    )
    columns = ("SWD", "vs oracle", "ps vs oracle", "vs field", "ps vs field", "coh", "ratio", "period", "reg")
    header = " | ".join(f"{m} {c}" for m in meshes for c in columns)
    print(f"| row | {header} |")
    print("|" + " --- |" * (1 + len(columns) * len(meshes)))
    for row, per_mesh in record["rows"].items():
        cells = []
        for m in meshes:
            s = per_mesh[m]
            oracle_relative = fmt(s.get("oracle_swd", math.nan), 0)
            cells += [fmt(s["swd"], 0), oracle_relative, fmt(s.get("oracle_ps", math.nan))]
            cells += [fmt(s.get("field_swd", math.nan), 0), fmt(s.get("field_ps", math.nan))]
            cells += [fmt(s["coherence"]), fmt(s["ratio"]), fmt(s["period"], 1), fmt(s.get("regularity", math.nan))]
        print(f"| {row} | " + " | ".join(cells) + " |")
    for loss in losses:
        parts = []
        for m in meshes:
            swd, rows = record["rows"][loss][m]["swd"], record["rows"]
            relative = rows[loss][m].get("oracle_swd", math.nan) / rows["oracle"][m].get("oracle_swd", math.nan)
            ps_relative = rows[loss][m].get("oracle_ps", math.nan) / rows["oracle"][m].get("oracle_ps", math.nan)
            parts.append(
                f"{m}: /oracle {fmt(swd / rows['oracle'][m]['swd'])}, /ot "
                f"{fmt(swd / rows['ot'][m]['swd']) if 'ot' in rows else '-'}, vs oracle /oracle's {fmt(relative)}, "
                f"ps vs oracle /oracle's {fmt(ps_relative)}"
            )
        print(f"  {loss}: " + "; ".join(parts))


if __name__ == "__main__":
    raise SystemExit(main())
