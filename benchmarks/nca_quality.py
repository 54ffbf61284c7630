"""How well a trained mesh cellular automaton textures meshes, against its exemplar and simple baselines.

    python benchmarks/nca_quality.py --model RUN/model.safetensors [--meshes CHAIR.npz CAR.npz [--splits 1 2]]
        [--graft OTHER/model.safetensors] [--child CHILD_RUN --scratch SCRATCH_RUN] [--out FILE.json]

All style losses are the training loss (:func:`mesh2tex.losses.ot_style.style_loss`, the model's VGG
depth, random-weight VGG19 unless $MESH2TEX_VGG_WEIGHTS is set) over 8 fixed views (azimuths 0..315,
elevations alternating 15 and -15 degrees) at 128 px, each averaged over 3 feature-sampling seeds.
Rows:
  trained        the model, 60 steps from its seed, on the training sphere
  untrained      a freshly initialised automaton of the same config, 60 steps
  oracle         with --exemplar-name (one of mesh2tex.synthetic.exemplars): the exemplar's own pattern
                 as a solid texture on the sphere at the exemplar's pixel scale, evaluated per pixel
                 (what a perfect texture would score; a loss that does not rank it first is suspect)
  vertex oracle  with --exemplar-name: the same pattern sampled at the vertices only and shown through
                 a linear readout (what the mesh's cell spacing leaves of it; not a bound)
  flat           the exemplar's mean colour on every vertex
  vertex noise   each vertex the colour of a random exemplar pixel
  SWD            object patches of the renders against patches of the exemplar (x1000, lower is better)
  stability      300 steps (5x the 60) against 60; the largest |state|
  regrowth       after 60 steps the quarter of the cells with the largest x zeroed, 60 more steps,
                 against 120 undamaged steps
  unseen meshes  each --meshes file and a finer sphere (sphere:48) against the training sphere: at the
                 mesh's own cells (native) and, where the model records its training cell spacing
                 and it differs by over sqrt(2), after splitting the faces to match it (matched, as
                 ``infer nca --subdivide auto`` does); with --exemplar-name also the oracle's and the
                 vertex oracle's ratio (the same pattern on that mesh against on the sphere: how much
                 of the rise the mesh itself causes); with --splits, also each --meshes file split
                 that many times
  graft          with --graft: per side of the seam x = 0 (cells with |x| > 0.3), the style loss against
                 each exemplar
  lineage        with --child and --scratch (two runs on one exemplar, the child from --parent MODEL):
                 the first logged iteration whose 50-iteration running mean of the style loss
                 reaches the scratch run's final one (the mean of its last 50 iterations)
  speed          ms per step on 6,146 cells (sphere:32), one thread, 200 steps after 20 warm-up
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mesh2tex.geometry.primitives import density_subdivisions, load_surface, mean_edge_length  # noqa: E402
from mesh2tex.losses.ot_style import ExemplarFeatures, style_loss  # noqa: E402
from mesh2tex.metrics.generation import object_set_swd  # noqa: E402
from mesh2tex.models import load_nca  # noqa: E402
from mesh2tex.nn.cell_graph import build_cell_graph  # noqa: E402
from mesh2tex.nn.nca import MeshNCA, NCAConfig  # noqa: E402
from mesh2tex.nn.render_texture import render_states  # noqa: E402
from mesh2tex.nn.vgg import load_vgg19  # noqa: E402
from mesh2tex.render import orbit_camera  # noqa: E402

RESOLUTION = 128
STEPS = 60


def view_angles(count: int = 8) -> tuple[torch.Tensor, torch.Tensor]:
    """The judged views' azimuths and elevations in degrees, each (count,): evenly round, +-15 in turn."""
    azimuth = torch.arange(count, dtype=torch.float32) * (360.0 / count)
    elevation = torch.tensor([15.0, -15.0]).repeat(count // 2)
    return azimuth, elevation


def views_mvp(count: int = 8) -> torch.Tensor:
    return orbit_camera(*view_angles(count), distance=3.2, fov=40.0).mvp


def colour_model(rgb: torch.Tensor) -> tuple[MeshNCA, torch.Tensor]:
    """A readout that shows fixed per-vertex colours: a 3-channel automaton whose readout is the identity."""
    model = MeshNCA(NCAConfig(channels=3))
    with torch.no_grad():
        model.readout.linear.weight.copy_(torch.eye(3))
        model.readout.linear.bias.zero_()
    return model, rgb[None]


class Judge:
    """Renders states of a model on a mesh and scores them against an exemplar."""

    def __init__(self, vgg, exemplar: np.ndarray, depth: int):
        self.vgg = vgg
        self.target = torch.from_numpy(exemplar).permute(2, 0, 1)[None].float() / 127.5 - 1
        self.features = ExemplarFeatures.compute(vgg, self.target, depth)
        self.mvp = views_mvp()

    @torch.no_grad()
    def render(self, model, state, graph):
        return render_states(model, state, graph, self.mvp, RESOLUTION)

    @torch.no_grad()
    def loss(self, model, state, graph, pixel_mask: torch.Tensor | None = None) -> float:
        views = self.render(model, state, graph)
        mask = views.mask if pixel_mask is None else views.mask * pixel_mask
        return float(
            np.mean(
                [
                    float(
                        style_loss(
                            self.vgg, views.images, mask, self.features, generator=torch.Generator().manual_seed(s)
                        )
                    )
                    for s in range(3)
                ]
            )
        )

    @staticmethod
    def pattern_scale(exemplar_pixels: float) -> float:
        """World units -> pattern units: the render's pixels per world unit at the mesh (distance 3.2,
        fov 40) over the exemplar's pixels per pattern unit."""
        return RESOLUTION / (2 * 3.2 * np.tan(np.radians(20.0))) / exemplar_pixels

    @torch.no_grad()
    def vertex_oracle_loss(self, name: str, graph, exemplar_pixels: float) -> float:
        """The style loss of the exemplar's pattern sampled at the vertices, through a linear readout."""
        from mesh2tex.synthetic.exemplars import EXEMPLARS

        points = graph.positions.double().numpy() * self.pattern_scale(exemplar_pixels)
        rgb = torch.from_numpy(EXEMPLARS[name](points, graph.normals.double().numpy())).float() * 2 - 1
        return self.loss(*colour_model(rgb), graph)

    @torch.no_grad()
    def oracle_loss(self, name: str, graph, exemplar_pixels: float) -> float:
        """The style loss of the exemplar's pattern painted per pixel on the mesh at the exemplar's scale
        (``exemplar_pixels``: exemplar pixels per unit of the pattern)."""
        from mesh2tex.render import interpolate, rasterize, transform_points
        from mesh2tex.synthetic.exemplars import EXEMPLARS

        raster = rasterize(transform_points(graph.positions, self.mvp), graph.triangles, (RESOLUTION, RESOLUTION))
        points = interpolate(graph.positions, raster, graph.triangles)  # (N, H, W, 3)
        normals = torch.nn.functional.normalize(interpolate(graph.normals, raster, graph.triangles), dim=-1)
        mask = raster.face_id >= 0
        scale = self.pattern_scale(exemplar_pixels)
        rgb = EXEMPLARS[name](points[mask].double().numpy() * scale, normals[mask].double().numpy())
        images = torch.ones(self.mvp.shape[0], RESOLUTION, RESOLUTION, 3)
        images[mask] = torch.from_numpy(rgb).float()
        images = images.permute(0, 3, 1, 2) * 2 - 1
        masks = mask[:, None].float()
        return float(
            np.mean(
                [
                    float(
                        style_loss(self.vgg, images, masks, self.features, generator=torch.Generator().manual_seed(s))
                    )
                    for s in range(3)
                ]
            )
        )

    @torch.no_grad()
    def swd(self, model, state, graph) -> float:
        views = self.render(model, state, graph)
        target = torch.nn.functional.interpolate(
            self.target, size=(RESOLUTION, RESOLUTION), mode="bilinear", align_corners=False
        )
        refs = ((target + 1) / 2).expand(8, -1, -1, -1)
        return object_set_swd((views.images.clamp(-1, 1) + 1) / 2, views.mask, refs, torch.ones_like(refs[:, :1]))


def grow(model: MeshNCA, graph, steps: int, seed: int = 0, state=None) -> torch.Tensor:
    generator = torch.Generator().manual_seed(seed)
    if state is None:
        state = model.seed_state(1, graph.num_cells, generator=torch.Generator().manual_seed(seed))
    with torch.no_grad():
        for _ in range(steps):
            state = model.step(state, graph, generator=generator)
    return state


def sphere_graph(model: MeshNCA, spec: str = "sphere", subdivide: int = 0):
    vertices, faces = load_surface(spec, subdivide=subdivide)
    return build_cell_graph(vertices, faces, model.cfg.neighbourhood)


def matched_subdivisions(spec: str, cell_spacing: float) -> tuple[int, float]:
    """(the splits that match the training cell spacing, the mesh's own edge length over it; 0 when unknown)."""
    spacing = mean_edge_length(*load_surface(spec))
    return density_subdivisions(spacing, cell_spacing), spacing / cell_spacing if cell_spacing > 0 else 0.0


def first_reaching(metrics: Path, target: float, window: int = 50) -> int | None:
    rows = [json.loads(line) for line in metrics.read_text().splitlines() if line.strip()]
    values = [r["loss_style"] for r in rows]
    every = rows[1]["iteration"] - rows[0]["iteration"] if len(rows) > 1 else 1
    span = max(1, window // every)  # logged rows in the window
    for i in range(span - 1, len(rows)):
        if np.mean(values[i - span + 1 : i + 1]) <= target:
            return int(rows[i]["iteration"])
    return None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", required=True)
    parser.add_argument("--meshes", nargs="*", default=[], help="unseen meshes (prepared .npz or mesh files)")
    parser.add_argument(
        "--splits", nargs="*", type=int, default=[], help="also run on each of --meshes split into four this many times"
    )
    parser.add_argument("--graft", help="a second model of the same lineage")
    parser.add_argument("--child", help="run folder trained with --parent MODEL")
    parser.add_argument("--scratch", help="run folder trained on the child's exemplar from scratch")
    parser.add_argument(
        "--exemplar-name", help="the model's exemplar by name (mesh2tex.synthetic.exemplars) for the oracle row"
    )
    parser.add_argument(
        "--exemplar-extent",
        type=float,
        default=1.0,
        help="the extent the exemplar image was made with (exemplar_image)",
    )
    parser.add_argument("--out", help="write the figures as JSON here")
    args = parser.parse_args()
    torch.set_num_threads(1)
    model, meta, exemplar = load_nca(args.model)
    depth = int(meta["config"]["vgg_depth"])
    vgg = load_vgg19(None, warn=False)
    judge = Judge(vgg, exemplar, depth)
    graph = sphere_graph(model, meta["config"]["mesh"])
    results: dict = {"model": args.model, "cells": graph.num_cells, "vgg": vgg.source}

    state60 = grow(model, graph, STEPS)
    results["trained"] = judge.loss(model, state60, graph)
    torch.manual_seed(1)
    untrained = MeshNCA(model.cfg)
    results["untrained"] = judge.loss(untrained, grow(untrained, graph, STEPS), graph)
    pixels = torch.from_numpy(exemplar.reshape(-1, 3)).float() / 127.5 - 1
    flat = colour_model(pixels.mean(0).expand(graph.num_cells, 3).clone())
    noise = colour_model(
        pixels[torch.randint(pixels.shape[0], (graph.num_cells,), generator=torch.Generator().manual_seed(0))]
    )
    results["flat"] = judge.loss(flat[0], flat[1], graph)
    results["vertex_noise"] = judge.loss(noise[0], noise[1], graph)
    if args.exemplar_name:
        results["oracle"] = judge.oracle_loss(args.exemplar_name, graph, exemplar.shape[0] / args.exemplar_extent)
        results["vertex_oracle"] = judge.vertex_oracle_loss(
            args.exemplar_name, graph, exemplar.shape[0] / args.exemplar_extent
        )
    best_baseline = min(results["flat"], results["vertex_noise"])
    results["ratio_to_untrained"] = results["trained"] / results["untrained"]
    results["ratio_to_best_baseline"] = results["trained"] / best_baseline
    results["swd_trained"] = judge.swd(model, state60, graph)
    results["swd_flat"] = judge.swd(flat[0], flat[1], graph)
    results["swd_ratio"] = results["swd_trained"] / results["swd_flat"]

    state300 = grow(model, graph, 5 * STEPS)
    results["stability_ratio"] = judge.loss(model, state300, graph) / results["trained"]
    results["max_abs_state_300"] = float(state300.abs().max())
    results["finite_300"] = bool(torch.isfinite(state300).all())

    undamaged = grow(model, graph, 2 * STEPS)
    x = graph.positions[:, 0]
    quarter = x >= torch.quantile(x, 0.75)
    damaged = state60.clone()
    damaged[0, quarter] = model.seed_state(1, graph.num_cells, generator=torch.Generator().manual_seed(2))[0, quarter]
    regrown = grow(model, graph, STEPS, seed=1, state=damaged)
    results["regrowth_ratio"] = judge.loss(model, regrown, graph) / judge.loss(model, undamaged, graph)

    unseen = {}
    cell_spacing = float(meta.get("cell_spacing", 0.0))
    exemplar_pixels = exemplar.shape[0] / args.exemplar_extent
    for spec in ["sphere:48", *args.meshes]:
        g = sphere_graph(model, spec)
        subdivisions, edge_ratio = matched_subdivisions(spec, cell_spacing)
        row = {
            "cells": g.num_cells,
            "edge_ratio": round(edge_ratio, 3),
            "ratio": judge.loss(model, grow(model, g, STEPS), g) / results["trained"],
        }
        if args.exemplar_name:
            row["oracle_ratio"] = judge.oracle_loss(args.exemplar_name, g, exemplar_pixels) / results["oracle"]
            row["vertex_oracle_ratio"] = (
                judge.vertex_oracle_loss(args.exemplar_name, g, exemplar_pixels) / results["vertex_oracle"]
            )
        if subdivisions:
            fine = sphere_graph(model, spec, subdivide=subdivisions)
            row["matched"] = {
                "subdivisions": subdivisions,
                "cells": fine.num_cells,
                "ratio": judge.loss(model, grow(model, fine, STEPS), fine) / results["trained"],
            }
            if args.exemplar_name:
                row["matched"]["vertex_oracle_ratio"] = (
                    judge.vertex_oracle_loss(args.exemplar_name, fine, exemplar_pixels) / results["vertex_oracle"]
                )
        if spec in args.meshes:
            for count in args.splits:
                fine = sphere_graph(model, spec, subdivide=count)
                row[f"split_{count}"] = {
                    "cells": fine.num_cells,
                    "ratio": judge.loss(model, grow(model, fine, STEPS), fine) / results["trained"],
                }
                if args.exemplar_name:
                    row[f"split_{count}"]["vertex_oracle_ratio"] = (
                        judge.vertex_oracle_loss(args.exemplar_name, fine, exemplar_pixels) / results["vertex_oracle"]
                    )
        unseen[Path(spec).stem] = row
    results["unseen"] = unseen

    if args.graft:
        other, other_meta, other_exemplar = load_nca(args.graft)
        other_judge = Judge(vgg, other_exemplar, depth)
        alpha = (graph.positions[:, 0] > 0).float()
        generator = torch.Generator().manual_seed(0)
        state = model.seed_state(1, graph.num_cells)
        with torch.no_grad():
            for _ in range(STEPS):
                state = model.step(state, graph, graft=(other, alpha), generator=generator)
        # Pixel side masks: render the side of each vertex as a colour.
        side, side_state = colour_model(torch.stack([alpha] * 3, 1) * 2 - 1)
        side_views = render_states(side, side_state, graph, judge.mvp, RESOLUTION)
        right = (side_views.images[:, :1] > 0.4).float()
        left = (side_views.images[:, :1] < -0.4).float()
        results["graft"] = {
            "left_vs_own": judge.loss(model, state, graph, left),
            "left_vs_other": other_judge.loss(model, state, graph, left),
            "right_vs_own": other_judge.loss(model, state, graph, right),
            "right_vs_other": judge.loss(model, state, graph, right),
            "lineage_shared": meta.get("lineage") == other_meta.get("lineage"),
        }
    if args.child and args.scratch:
        scratch_rows = [json.loads(line) for line in (Path(args.scratch) / "metrics.jsonl").read_text().splitlines()]
        target = float(np.mean([r["loss_style"] for r in scratch_rows[-5:]]))
        results["lineage"] = {
            "scratch_final_style": target,
            "child_reaches_at": first_reaching(Path(args.child) / "metrics.jsonl", target),
            "scratch_reaches_at": first_reaching(Path(args.scratch) / "metrics.jsonl", target),
        }

    big = sphere_graph(model, "sphere:32")
    state = model.seed_state(1, big.num_cells)
    with torch.no_grad():
        for _ in range(20):
            state = model.step(state, big)
        start = time.perf_counter()
        for _ in range(200):
            state = model.step(state, big)
    results["ms_per_step_6k"] = 1000 * (time.perf_counter() - start) / 200

    width = max(len(k) for k in results)
    for key, value in results.items():
        shown = (
            json.dumps(value) if isinstance(value, dict) else (f"{value:.4f}" if isinstance(value, float) else value)
        )
        print(f"{key:<{width}}  {shown}")
    if args.out:
        Path(args.out).write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
