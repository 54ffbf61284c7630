"""Do the mesh's creases tell an object's front from its back on photos of the object itself, not of the
prepared mesh? The crease agreement (:func:`mesh2tex.transfer.crease_agreement`, which the pose search weighs
between a pose and its half turn) on photos of the raw meshes, judged with the prepared mesh's normals.

    python benchmarks/crease_halfturn.py --checkpoint car --category car [--poses 8] [--resolution 128]
        [--offset 5] [--spread S] [--crease-side N]

``outside_transfer.py`` photographs the prepared mesh, whose facets then line up with the judged mesh's
exactly at the true pose. Here each mesh made apart from the world (``outside_generation.py``'s) is drawn
as its file holds it (its own faces, centred and scaled as the prepared mesh is), flat shaded under a light
from a random direction above (30 % ambient, grey), at the same cameras as ``outside_transfer.py``'s photos,
framed by its own outline. Two counts per mesh: the photos whose true pose scores above its half turn
(exact poses), and the same as the search weighs them, from a pose ``--offset`` degrees off in azimuth and
elevation (a random sign each), each side the best over half the search's step about it
(:func:`mesh2tex.transfer.pose.creases_near`).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))


def raw_photo(vertices, faces, view, distance, fov, resolution, margin, rng):
    """The raw mesh (vertices (V, 3) float32, faces (T, 3) int64 tensors) flat shaded at the view's pose under a
    random light from above, framed around its outline: a :class:`mesh2tex.transfer.Photo` at ``resolution``."""
    from mesh2tex.render import (
        crop_mask,
        crop_square,
        object_box,
        orbit_camera,
        rasterize,
        render_normals,
        transform_points,
    )
    from mesh2tex.transfer import Photo

    side = int(round(resolution * 1.5))
    camera = orbit_camera(torch.tensor([view.azimuth]), torch.tensor([view.elevation]), distance=distance, fov=fov)
    raster = rasterize(transform_points(vertices, camera.mvp), faces, (side, side))
    covered = (raster.face_id[0] >= 0).numpy()
    box = object_box(covered, margin)
    light = torch.nn.functional.normalize(
        torch.tensor(rng.normal(size=3) + (0.0, 2.0, 0.0), dtype=torch.float32), dim=0
    )
    shade = (render_normals(vertices, faces, raster, smooth=False) * light).sum(-1, keepdim=True).clamp(min=0)
    grey = (0.3 + 0.7 * shade) * 2 - 1
    image = crop_square(grey.permute(0, 3, 1, 2).expand(1, 3, side, side).contiguous(), box, resolution, fill=1.0)
    return Photo(image=image, mask=crop_mask(covered, box, resolution))


def main() -> None:
    import trimesh
    from outside_generation import outside_meshes

    from mesh2tex.models import load_generator
    from mesh2tex.synthetic.world import WorldSpec, sample_views
    from mesh2tex.texturing import load_shape
    from mesh2tex.transfer import TransferConfig, crease_agreement, normals_at_pose
    from mesh2tex.transfer.pose import creases_near

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--checkpoint", default="chair")
    parser.add_argument("--category", default="chair", choices=["chair", "car"])
    parser.add_argument("--poses", type=int, default=8)
    parser.add_argument("--resolution", type=int, default=128)
    parser.add_argument("--offset", type=float, default=5.0)
    parser.add_argument(
        "--spread", type=float, help="degrees about each pose (default: half the search's step, as the search)"
    )
    parser.add_argument("--crease-side", type=int, help="the side the creases are compared at (default: CREASE_SIDE)")
    args = parser.parse_args()
    if args.crease_side:
        import mesh2tex.transfer.pose

        mesh2tex.transfer.pose.CREASE_SIDE = args.crease_side
    model = load_generator(args.checkpoint, torch.device("cpu"))
    distance, fov = model.camera.distance, model.camera.fov
    cfg = TransferConfig(resolution=args.resolution)
    spread = 0.5 * cfg.pose_search_step if args.spread is None else args.spread
    rng = np.random.default_rng(0)
    spec = WorldSpec(category=args.category, variety="real")
    totals = np.zeros(3, dtype=int)
    print(f"{'mesh':14s} {'photos':>6s} {'exact: true above turn':>22s} {'searched, off by ' + str(args.offset):>24s}")
    for index, (name, path) in enumerate(outside_meshes(args.category, Path(tempfile.mkdtemp()))):
        shape, _ = load_shape(path, model.network, model.face_count(), output_mesh="prepared")
        raw = trimesh.load(path, force="mesh")
        prepared = shape.vertices[0]
        scale = np.ptp(prepared, axis=0).max() / np.ptp(raw.vertices, axis=0).max()
        vertices = torch.as_tensor((raw.vertices - raw.bounds.mean(axis=0)) * scale, dtype=torch.float32)
        faces = torch.as_tensor(raw.faces, dtype=torch.int64)
        counts = np.zeros(3, dtype=int)
        for view in sample_views(spec, 1000 + index, args.poses, query=True):
            photo = raw_photo(vertices, faces, view, distance, fov, args.resolution, cfg.margin, rng)
            exact = [
                crease_agreement(
                    photo, *normals_at_pose(shape, view.azimuth + turn, view.elevation, distance, fov, cfg)
                )
                for turn in (0.0, 180.0)
            ]
            d_az, d_el = args.offset * rng.choice([-1.0, 1.0], size=2)
            near = [
                creases_near(
                    shape, photo, view.azimuth + d_az + turn, view.elevation + d_el, spread, distance, fov, cfg
                )
                for turn in (0.0, 180.0)
            ]
            counts += (1, exact[0] > exact[1], near[0] > near[1])
        totals += counts
        print(f"{name:14s} {counts[0]:6d} {counts[1]:22d} {counts[2]:24d}")
    print(f"{'all':14s} {totals[0]:6d} {totals[1]:22d} {totals[2]:24d}")


if __name__ == "__main__":
    main()
