"""How close is the synthetic world's geometry to chairs and cars it did not make?

    python benchmarks/world_geometry.py [--shapes 12] [--seed 0] [--faces 1536]

For each category, three sets of meshes go through the user's path (``prepare_shape``: cleaning,
QuadriFlow, the face features the generator reads): the boxy world (``--variety boxy``), the varied
world (``--variety real``), and hand-modelled meshes made apart from the world's code
(``benchmarks/world_reference_shapes.py``). Per set it prints

* curved: the share of quads with |mean curvature x quad size| > 0.1 (the ``mean_curvature``
  feature, asinh-compressed), i.e. faces that are not flat;
* thin: the share of surface area whose inward thickness (a ray from the face centre along the
  inner normal to the next surface) is under 2% of the bounding-box diagonal: legs, tubes, panels;
* W1/sd: for four face features (mean and Gaussian curvature, sff_diff, the normal's height
  component), the 1-D Wasserstein distance between the set's pooled per-face values and the
  hand-modelled set's, divided by the hand-modelled values' standard deviation, and their mean.
  The hand-modelled row compares its two halves (every other shape), a floor for the noise of so few shapes.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import trimesh
from scipy.stats import wasserstein_distance

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.world_reference_shapes import reference_shapes  # noqa: E402
from mesh2tex.errors import InputError  # noqa: E402
from mesh2tex.geometry.features import FEATURE_NAMES  # noqa: E402
from mesh2tex.geometry.prepare import prepare_shape  # noqa: E402
from mesh2tex.synthetic.world import WorldSpec, make_shape  # noqa: E402

COMPARED = ("mean_curvature", "gaussian_curvature", "sff_diff", "normal_y")
CURVED, THIN = 0.1, 0.02


def shape_statistics(vertices: np.ndarray, faces: np.ndarray, face_count: int) -> dict | None:
    """Prepare one mesh as a user's would be and measure it: per-face features, curved share, thin share."""
    try:
        prepared = prepare_shape(vertices, faces, face_count=face_count, levels=2, timeout=120)
    except InputError:
        return None
    features = prepared.face_features
    quad_vertices, quads = prepared.vertices[0].astype(np.float64), prepared.quads[0]
    triangles = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    mesh = trimesh.Trimesh(quad_vertices, triangles, process=False)
    corners = quad_vertices[quads]
    centres = corners.mean(axis=1)
    normals = features[:, :3].astype(np.float64)
    areas = 0.5 * np.linalg.norm(np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1]), axis=1)
    origins = centres - normals * 1e-4
    hits, rays, _ = mesh.ray.intersects_location(origins, -normals, multiple_hits=False)
    thickness = np.full(len(quads), np.inf)
    thickness[rays] = np.linalg.norm(hits - origins[rays], axis=1)
    column = {name: k for k, name in enumerate(FEATURE_NAMES)}
    return {
        "features": features,
        "curved": float(np.mean(np.abs(features[:, column["mean_curvature"]]) > CURVED)),
        "thin": float(areas[thickness < THIN].sum() / areas.sum()),
    }


def distances(values: dict[str, np.ndarray], reference: dict[str, np.ndarray]) -> dict[str, float]:
    return {
        name: wasserstein_distance(values[name], reference[name]) / max(reference[name].std(), 1e-9)
        for name in COMPARED
    }


def pooled(stats: list[dict]) -> dict[str, np.ndarray]:
    column = {name: k for k, name in enumerate(FEATURE_NAMES)}
    return {name: np.concatenate([s["features"][:, column[name]] for s in stats]) for name in COMPARED}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shapes", type=int, default=12, help="shapes of each world")
    parser.add_argument("--seed", type=int, default=0, help="the worlds' seed")
    parser.add_argument("--faces", type=int, default=1536, help="quads of the prepared meshes")
    parser.add_argument("--categories", nargs="+", default=["chair", "car"])
    args = parser.parse_args()
    for category in args.categories:
        started = time.time()
        sets = {}
        for variety in ("boxy", "real"):
            spec = WorldSpec(category=category, seed=args.seed, variety=variety, shapes=max(args.shapes, 2))
            shapes = [make_shape(spec, i) for i in range(args.shapes)]
            sets[f"{variety} world"] = [shape_statistics(s.vertices, s.faces, args.faces) for s in shapes]
        sets["hand-modelled"] = [
            shape_statistics(m.vertices, m.faces, args.faces) for _, m in reference_shapes(category)
        ]
        prepared = {name: [s for s in stats if s is not None] for name, stats in sets.items()}
        reference = pooled(prepared["hand-modelled"])
        print(f"\n{category}s: {args.faces} quads per prepared shape, seed {args.seed} ({time.time() - started:.0f} s)")
        header = (
            f"{'set':16s} {'prepared':>9s} {'curved':>7s} {'thin':>6s} "
            + " ".join(f"{n[:13]:>13s}" for n in COMPARED)
            + f" {'mean W1/sd':>10s}"
        )
        print(header)
        for name, stats in prepared.items():
            if name == "hand-modelled":
                distance = distances(pooled(stats[0::2]), pooled(stats[1::2]))
            else:
                distance = distances(pooled(stats), reference)
            print(
                f"{name:16s} {len(stats):>4d}/{len(sets[name]):<4d} {np.mean([s['curved'] for s in stats]):7.2f} "
                f"{np.mean([s['thin'] for s in stats]):6.2f} "
                + " ".join(f"{distance[n]:13.3f}" for n in COMPARED)
                + f" {np.mean(list(distance.values())):10.3f}"
            )


if __name__ == "__main__":
    main()
