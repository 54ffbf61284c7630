"""Which of a photo's mask estimates should the mesh pick? Each estimate's own IoU with the truth, the pose the
search finds from it and how well that pose's outline matches, then the estimate each rule would pick.

    python benchmarks/mask_pick.py --images DIR --checkpoint chair [--category chair] [--poses 8]
        [--variants room clutter far]

``DIR`` holds the photos of ``outside_transfer.py --images DIR --poses 8 --transfers 0 --variants room clutter
far`` (the same ``--checkpoint`` and ``--category``): each mesh's PLY file, its photos with their alpha (the
truth) and the photos over each backdrop. For every photo, as ``infer transfer`` does: the estimates of
:func:`mesh2tex.transfer.photo_masks` (the network's with GrabCut edges, the network's alone, GrabCut's), and
for each the pose :func:`mesh2tex.transfer.estimate_pose` finds from it (its ``silhouette_iou``: the found
pose's outline against the estimate, each cropped around itself). Rules, each row the estimates it picks:

  outline        the highest ``silhouette_iou`` (:func:`mesh2tex.transfer.pick_by_outline`, what runs now)
  outline x agreement   ``silhouette_iou`` times the estimate's mean IoU with the other estimates
  outline x network     ``silhouette_iou`` times the estimate's soft IoU with the network's probability
  first          the network's with GrabCut edges, always
  oracle         the estimate nearest the truth (not a method: what the best pick of the estimates gives)

Columns: the picked estimates' mean IoU with the truth, their poses within 15 degrees (up to the mesh's
symmetries), the IoU of the found pose's outline, laid where the estimate is, with the truth (what the mask's
mending starts from), and the photos whose pick is 0.2 or more IoU below the best estimate's.
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
sys.path.insert(0, str(ROOT / "benchmarks"))


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


RULES = {
    "outline": lambda e: e["outline"],
    "outline x agreement": lambda e: e["outline"] * e["agreement"],
    "outline x network": lambda e: e["outline"] * e["network"],
    "first": lambda e: -e["index"],
    "oracle": lambda e: e["truth"],
}


def main() -> None:
    import cv2
    from outside_generation import outside_meshes
    from outside_photos import far_photo

    from mesh2tex.geometry.symmetry import azimuth_symmetries
    from mesh2tex.models import MODEL_FILES, load_generator, models_root
    from mesh2tex.nn.pose import symmetric_azimuth_error
    from mesh2tex.render import object_box
    from mesh2tex.synthetic.world import WorldSpec, sample_views
    from mesh2tex.texturing import load_shape
    from mesh2tex.transfer import TransferConfig, estimate_pose, frame_photo, photo_masks
    from mesh2tex.transfer.photo import silhouette_in_photo

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--images", required=True, help="outside_transfer.py's --images folder")
    parser.add_argument("--checkpoint", default="chair")
    parser.add_argument("--category", default="chair", choices=["chair", "car"])
    parser.add_argument("--poses", type=int, default=8)
    parser.add_argument("--variants", nargs="+", default=["room", "clutter", "far"])
    parser.add_argument("--out", help="write the per-photo estimates here (JSON)")
    args = parser.parse_args()
    folder, device = Path(args.images), torch.device("cpu")
    model = load_generator(args.checkpoint, device)
    distance, fov = model.camera.distance, model.camera.fov
    cfg = TransferConfig(resolution=64)  # outside_transfer.py's default crop
    mask_checkpoint = str(models_root() / args.checkpoint / MODEL_FILES["mask"])
    spec = WorldSpec(category=args.category, variety="real")
    photos = []
    for index, (name, _) in enumerate(outside_meshes(args.category, Path(tempfile.mkdtemp()))):
        shape, _ = load_shape(folder / f"{name}.ply", model.network, model.face_count(), output_mesh="prepared")
        turns = azimuth_symmetries(shape.vertices[0])
        for k, view in enumerate(sample_views(spec, 1000 + index, args.poses, query=True)):
            alpha = cv2.imread(str(folder / f"{name}_{k}.png"), cv2.IMREAD_UNCHANGED)[..., 3] >= 128
            for variant in args.variants:
                truth = alpha
                if variant == "far":  # where outside_transfer.py's far photo put the object: the same draws
                    coverage = alpha[..., None].astype(np.float32)
                    _, truth = far_photo(np.zeros_like(coverage), coverage, np.random.default_rng([13, index, k]))
                masked = photo_masks(folder / f"{name}_{k}_{variant}.jpg", None, mask_checkpoint=mask_checkpoint)
                masks = [mask for mask, _ in masked.masks]
                estimates = []
                for i, mask in enumerate(masks):
                    found = estimate_pose(
                        args.checkpoint, shape, frame_photo(masked.rgb, mask, cfg), distance, fov, cfg, device
                    )
                    box = object_box(mask, cfg.margin)
                    outline = silhouette_in_photo(
                        shape, found.azimuth, found.elevation, distance, fov, box, mask.shape, cfg
                    )
                    others = [iou(mask, other) for j, other in enumerate(masks) if j != i]
                    p = masked.probability
                    estimates.append(
                        {
                            "index": i,
                            "truth": iou(mask, truth),
                            "outline": found.silhouette_iou or 0.0,
                            "agreement": float(np.mean(others)) if others else 1.0,
                            "network": float(np.minimum(mask, p).sum() / max(np.maximum(mask, p).sum(), 1e-6)),
                            "pose_error": symmetric_azimuth_error(found.azimuth, view.azimuth, turns),
                            "outline_truth": iou(outline, truth),
                        }
                    )
                photos.append({"mesh": name, "photo": k, "variant": variant, "estimates": estimates})
                print(name, k, variant, [round(e["truth"], 2) for e in estimates], flush=True)
    if args.out:
        Path(args.out).write_text(json.dumps(photos, indent=1))
    print(f"{'backdrop':9s} {'rule':20s} {'IoU':>6s} {'<=15 deg':>8s} {'outline IoU':>11s} {'0.2 below best':>14s}")
    for variant in [*args.variants, "all"]:
        chosen = [p for p in photos if variant in ("all", p["variant"])]
        for rule, score in RULES.items():
            picks = [max(p["estimates"], key=score) for p in chosen]
            best = [max(e["truth"] for e in p["estimates"]) for p in chosen]
            print(
                f"{variant:9s} {rule:20s} {np.mean([e['truth'] for e in picks]):6.3f} "
                f"{sum(e['pose_error'] <= 15 for e in picks):8d} {np.mean([e['outline_truth'] for e in picks]):11.3f} "
                f"{sum(b - e['truth'] >= 0.2 for b, e in zip(best, picks)):14d}"
            )


if __name__ == "__main__":
    main()
