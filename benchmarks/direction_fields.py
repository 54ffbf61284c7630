"""The direction fields of ``infer synthesize``'s charts and walked patches, side by side: how much each
turns across the mesh's edges, what it costs, and (``--figure``) what a pattern laid along each looks like.

    python benchmarks/direction_fields.py --meshes sphere CHAIR.npz [--axis y] [--figure FILE.png]
        [--exemplar stripes] [--iters 400] [--size 512] [--seed 0] [--elevation 45]

Per mesh (read as the automaton's benchmarks read it: :func:`mesh2tex.geometry.primitives.load_surface`,
its quads split as everywhere, :func:`mesh2tex.geometry.prepared.quads_to_triangles`) and field (``up``,
``smooth``; :mod:`mesh2tex.geometry.direction_field`):
the seconds to compute it (one thread), and across every interior edge the angle between the
neighbour's direction and this face's carried over the edge (:func:`field_turns`): the share of edges
turning by more than 30 degrees (jumps and singular points) and the median (how fast it turns where it
is smooth). A field of the mesh's up turns where the surface curves (the sphere) and jumps by a right
angle at the edge of every face that looks along the axis (a chair's seat).

With ``--figure``, the exemplar (:func:`mesh2tex.synthetic.exemplars.exemplar_image`) is synthesised on
each mesh along each field by ``infer synthesize --method patches`` (its defaults but ``--iters``,
``--size``, ``--seed``; a new xatlas atlas) and rendered from four azimuths at ``--elevation`` degrees,
so that a seat's top shows: one row per mesh and field, the exemplar first.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.nca_structure import write_figure  # noqa: E402
from mesh2tex.geometry.direction_field import AXES, FIELDS, field_turns, tangent_field  # noqa: E402
from mesh2tex.geometry.geodesic import SurfaceWalker  # noqa: E402
from mesh2tex.geometry.prepared import quads_to_triangles  # noqa: E402
from mesh2tex.geometry.primitives import load_surface  # noqa: E402
from mesh2tex.render import orbit_camera  # noqa: E402
from mesh2tex.render.bake import new_atlas  # noqa: E402
from mesh2tex.synthetic.exemplars import exemplar_image  # noqa: E402
from mesh2tex.texel_synthesis import (  # noqa: E402
    SynthesisConfig,
    TexelSurface,
    TexelSynthesis,
    exemplar_tensor,
    render_texture,
)

RESOLUTION = 192  # the figure's tiles
AZIMUTHS = (30.0, 120.0, 210.0, 300.0)  # the figure's views


def synthesised_views(positions, faces, field: str, args) -> torch.Tensor:
    """(4, 3, R, R) in [0, 1]: the exemplar synthesised along ``field`` on the mesh, seen from four azimuths."""
    vertex_index, atlas_faces, uv = new_atlas(positions, faces)
    surface = TexelSurface.from_arrays(positions[vertex_index], atlas_faces, uv)
    cfg = SynthesisConfig(
        iters=args.iters,
        texture_size=args.size,
        seed=args.seed,
        method="patches",
        direction_field=field,
        direction_axis=args.axis,
    )
    exemplar = exemplar_tensor(exemplar_image(args.exemplar, cfg.exemplar_size), cfg.exemplar_size)
    synthesis = TexelSynthesis(cfg, surface, exemplar)
    for _ in range(args.iters):
        synthesis.step()
    azimuth = torch.tensor(AZIMUTHS)
    mvp = orbit_camera(azimuth, torch.full((4,), float(args.elevation)), distance=3.2, fov=40.0).mvp
    with torch.no_grad():
        images, _ = render_texture(surface, synthesis.texture().permute(2, 0, 1), mvp, RESOLUTION)
    return (images + 1) / 2


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--meshes", nargs="+", default=["sphere"], help="sphere, a prepared shape or a mesh file")
    parser.add_argument("--axis", default="y", choices=AXES, help="the axis that guides the fields")
    parser.add_argument("--figure", help="write the synthesised views here (PNG)")
    parser.add_argument("--exemplar", default="stripes")
    parser.add_argument("--iters", type=int, default=SynthesisConfig.iters)
    parser.add_argument("--size", type=int, default=SynthesisConfig.texture_size, help="texture side")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--elevation", type=float, default=45.0, help="the figure's views' elevation (degrees)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    rows = []
    exemplar = torch.from_numpy(exemplar_image(args.exemplar, RESOLUTION)).permute(2, 0, 1) / 255  # the first tile
    columns = ["exemplar"] + [f"azimuth {a:.0f}" for a in AZIMUTHS]
    print("| mesh | faces | field | seconds | edges turning > 30 deg | median turn (deg) |")
    print("| --- | ---: | --- | ---: | ---: | ---: |")
    for spec in args.meshes:
        positions, faces = load_surface(spec)
        faces = np.asarray(faces, dtype=np.int64)
        positions, faces = (
            np.asarray(positions, dtype=np.float64),
            faces if faces.shape[1] == 3 else quads_to_triangles(faces),
        )
        walker = SurfaceWalker(positions, faces)
        name = Path(spec).stem
        for field in FIELDS:
            start = time.perf_counter()
            directions = tangent_field(walker, field, args.axis)
            seconds = time.perf_counter() - start
            turns = field_turns(walker, directions)
            print(
                f"| {name} | {len(faces)} | {field} | {seconds:.3f} | {(turns > 30).mean():.4f} | "
                f"{np.median(turns):.2f} |",
                flush=True,
            )
            if args.figure:
                rows.append((f"{name}: {field}", list(synthesised_views(positions, faces, field, args))))
                write_figure(Path(args.figure), [(title, [exemplar, *views]) for title, views in rows], columns)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
