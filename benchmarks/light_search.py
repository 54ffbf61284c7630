"""The photo's light as `transfer.light_start: search` finds it, against the truth, before any transfer.

    OMP_NUM_THREADS=1 python benchmarks/light_search.py [--checkpoint chair] [--category chair] [--poses 2]
        [--resolution 128]

The meshes, materials and photos of ``benchmarks/outside_transfer.py`` (the hand-modelled chairs or cars, each
read as a user's file is; the world's query cameras and lights; the object's alpha mask given). For each photo
the pose is found as ``infer transfer`` finds it (``locate_object``), the photo is framed at ``--resolution``
(128: ``infer transfer``'s default crop) and :func:`mesh2tex.transfer.light.search_light` runs on it. Columns:
the fold pairs it used (0: too few, it keeps the prior's middle), the light found (azimuth offset from the
camera, elevation, ambient), its angle to the photo's light (both relative to their camera: a pose found
turned by one of the mesh's symmetries does not count against it), and the same angle for the prior's middle
(the baseline: where the light starts with ``light_start: prior``). Last line: the medians.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT))


def main() -> None:
    from outside_generation import height_parts, outside_meshes
    from outside_transfer import light_angle, true_light

    from mesh2tex.evaluation.compare import render_for_comparison
    from mesh2tex.evaluation.surfaces import material_surface
    from mesh2tex.io.images import save_png
    from mesh2tex.models import load_generator
    from mesh2tex.nn.batch import collate_shapes
    from mesh2tex.nn.render_texture import rasterize_batch
    from mesh2tex.render import RenderSettings
    from mesh2tex.synthetic.world import WorldSpec, sample_material, sample_views
    from mesh2tex.texturing import load_shape
    from mesh2tex.transfer import TransferConfig, locate_object, photo_masks, view_at_pose
    from mesh2tex.transfer.light import LightStart, search_light

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--checkpoint", default="chair")
    parser.add_argument("--category", default="chair", choices=["chair", "car"])
    parser.add_argument("--poses", type=int, default=2)
    parser.add_argument("--resolution", type=int, default=128)
    args = parser.parse_args()
    device = torch.device("cpu")
    model = load_generator(args.checkpoint, device)
    cfg = TransferConfig(resolution=args.resolution)
    spec = WorldSpec(category=args.category, variety="real")
    folder = Path(tempfile.mkdtemp(prefix="light-search-"))

    distance, fov = model.camera.distance, model.camera.fov
    rows = []
    for index, (name, path) in enumerate(outside_meshes(args.category, folder)):
        shape, _ = load_shape(path, model.network, model.face_count(), output_mesh="prepared")
        batch = collate_shapes([shape])
        vertices, faces = shape.vertices[0], shape.triangles(0)
        parts = height_parts(vertices, faces, args.category)
        truth_surface = material_surface(
            vertices, faces, parts, sample_material(spec, np.random.default_rng([7, index]))
        )
        for k, view in enumerate(sample_views(spec, 1000 + index, args.poses, query=True)):
            render = render_for_comparison(truth_surface, [view], RenderSettings(256, 2))
            rgb, mask = render.rgb[0].permute(1, 2, 0).numpy(), render.mask[0, 0].numpy() > 0.5
            file = folder / f"{name}_{k}.png"
            rgba = [(rgb * 255).round().astype(np.uint8), (mask * 255).astype(np.uint8)[..., None]]
            save_png(file, np.concatenate(rgba, 2))
            located = locate_object(photo_masks(file, None), shape, args.checkpoint, None, distance, fov, cfg, device)
            found = located.estimate
            framed = view_at_pose(shape, found.azimuth, found.elevation, distance, fov, cfg)
            samples = rasterize_batch(batch, framed.mvp, (framed.render_size, framed.render_size))
            start, truth = search_light(located.photo, framed, batch, samples), true_light(view)
            row = {
                "mesh": name,
                "photo": k,
                "pairs": start.pairs,
                "found": [start.azimuth_offset, start.elevation, start.ambient],
                "truth": [round(truth.azimuth_offset, 1), round(truth.elevation, 1), truth.ambient],
                "angle": light_angle(start, truth),
                "prior_middle_angle": light_angle(LightStart.prior_middle(), truth),
            }
            rows.append(row)
            print(json.dumps(row), flush=True)
    nearer = sum(r["angle"] < r["prior_middle_angle"] for r in rows)
    print(
        f"\n{len(rows)} photos at {args.resolution} px: median angle to the photo's light, search "
        f"{np.median([r['angle'] for r in rows]):.1f} degrees, prior's middle "
        f"{np.median([r['prior_middle_angle'] for r in rows]):.1f}; the search nearer on {nearer}"
    )


if __name__ == "__main__":
    main()
