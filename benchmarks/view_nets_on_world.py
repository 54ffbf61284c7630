"""How well the pose and NOC networks read the synthetic world's photos (they never train on them).

    python benchmarks/view_nets_on_world.py --world WORLD --pose-checkpoint P [--noc-checkpoint N]
                                            [--shapes DIR ...] [--show-misses DEG] [--resolution 64] [--queries-only]
                                            [--pose-halfturn-tie T]

Every photo of the world with a known camera (``images/`` of the training shapes and ``queries/`` of
the held-out shapes; their poses are in ``index.json``) goes through exactly the path of
``infer transfer``: the crop around its mask (``load_photo``), then ``predict_pose`` and
``predict_noc``. Prints, per set and overall: the azimuth bin accuracy (the true angle's bin), the
share within 30 and 45 degrees, the mean azimuth and elevation errors, and for the queries (whose
ground-truth NOC maps are stored) the mean NOC error over object pixels, in NOC units (the object's
box has diagonal 1). The figure to compare against is chance: 1/12 of azimuth bins, a mean error of
90 degrees.

With ``--shapes`` (folders of the world's prepared shapes, e.g. ``demo_out/shapes/train
demo_out/shapes/query``) the pose also goes through the silhouette search of ``infer transfer
--pose auto`` (``estimate_pose``, at the GAN camera's distance 1.7 and field of view 40), and its
errors and seconds per photo are printed beside the network's.
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

from mesh2tex.geometry.prepared import PreparedShape  # noqa: E402
from mesh2tex.io.images import load_image, load_mask  # noqa: E402
from mesh2tex.nn.pose import PoseBins  # noqa: E402
from mesh2tex.render import (  # noqa: E402
    CameraConfig,  # noqa: E402
    crop_square,
    object_box,
)
from mesh2tex.transfer import TransferConfig, estimate_pose, load_photo, predict_noc, predict_pose  # noqa: E402


def azimuth_error(predicted: float, true: float) -> float:
    """Absolute difference of two azimuths in degrees, in [0, 180]."""
    return abs((predicted - true + 180.0) % 360.0 - 180.0)


def true_noc(world: Path, entry: dict, cfg: TransferConfig) -> torch.Tensor:
    """(R,R,3) ground-truth NOC of a query photo, cropped exactly like the photo."""
    noc, _ = load_image(world / entry["noc"])
    mask = np.asarray(load_mask(world / entry["mask"]), dtype=bool)
    box = object_box(mask, cfg.margin)
    noc_t = torch.from_numpy(np.array(noc)).permute(2, 0, 1)[None].float() / 255.0
    return crop_square(noc_t, box, cfg.resolution)[0].permute(1, 2, 0)


GAN_CAMERA = CameraConfig()  # the camera an untrained or default GAN renders with


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--world", required=True, help="a world from 'mesh2tex prepare synthetic'")
    parser.add_argument("--pose-checkpoint", required=True)
    parser.add_argument("--noc-checkpoint")
    parser.add_argument(
        "--resolution", type=int, default=64, help="side of the photo crop (as infer transfer --resolution)"
    )
    parser.add_argument("--queries-only", action="store_true", help="only the held-out query photos")
    parser.add_argument(
        "--shapes",
        nargs="+",
        default=[],
        help="folders of the world's prepared shapes: also time and score the silhouette search",
    )
    parser.add_argument(
        "--show-misses",
        type=float,
        metavar="DEG",
        help="with --shapes: list each photo the search puts more than DEG degrees off, with both poses and IoUs",
    )
    parser.add_argument(
        "--pose-halfturn-tie",
        type=float,
        default=TransferConfig.pose_halfturn_tie,
        help="with --shapes: the search weighs the half turn by the creases within this IoU (negative: never)",
    )
    args = parser.parse_args()

    world = Path(args.world)
    index = json.loads((world / "index.json").read_text())
    cfg = TransferConfig(resolution=args.resolution, pose_halfturn_tie=args.pose_halfturn_tie)
    device = torch.device("cpu")
    sets = {"queries (held-out shapes)": index["queries"]}
    if not args.queries_only:
        sets = {"photos (training shapes)": index["images"], **sets}
    bins = PoseBins()
    shape_files = {f.stem: f for folder in args.shapes for f in Path(folder).glob("*.npz")}
    rows, searched = [], []
    for name, entries in sets.items():
        errors, elevation_errors, hits, noc_errors = [], [], [], []
        search_errors, search_elevation_errors, search_seconds = [], [], []
        for entry in entries:
            photo, _ = load_photo(world / entry["image"], world / entry["mask"], cfg)
            azimuth, elevation = predict_pose(args.pose_checkpoint, photo, device)
            errors.append(azimuth_error(azimuth, entry["azimuth"]))
            elevation_errors.append(abs(elevation - entry["elevation"]))
            hits.append(int(bins.azimuth_to_bin(azimuth)) == int(bins.azimuth_to_bin(entry["azimuth"])))
            if args.noc_checkpoint and "noc" in entry:
                predicted = predict_noc(args.noc_checkpoint, photo, device)
                target = true_noc(world, entry, cfg)
                both = photo.mask[0, 0] > 0.5
                noc_errors.append(float((predicted[both] - target[both]).norm(dim=1).mean()))
            if entry["shape"] in shape_files:
                shape = PreparedShape.load(shape_files[entry["shape"]])
                start = time.perf_counter()
                estimate = estimate_pose(
                    args.pose_checkpoint, shape, photo, GAN_CAMERA.distance, GAN_CAMERA.fov, cfg, device
                )
                search_seconds.append(time.perf_counter() - start)
                search_errors.append(azimuth_error(estimate.azimuth, entry["azimuth"]))
                if args.show_misses is not None and search_errors[-1] > args.show_misses:
                    print(
                        f"miss: {entry['image']} true az {entry['azimuth']:.0f} el {entry['elevation']:.0f}; search "
                        f"{estimate.azimuth:.0f}, {estimate.elevation:.0f} (IoU {estimate.silhouette_iou}); network "
                        f"{estimate.network[0]:.0f}, {estimate.network[1]:.0f} (IoU {estimate.network_silhouette_iou})"
                    )
                search_elevation_errors.append(abs(estimate.elevation - entry["elevation"]))
        e = np.array(errors)
        rows.append(
            (
                name,
                len(entries),
                np.mean(hits),
                np.mean(e <= 30),
                np.mean(e <= 45),
                e.mean(),
                np.mean(elevation_errors),
                np.mean(noc_errors) if noc_errors else float("nan"),
            )
        )
        if search_errors:
            s = np.array(search_errors)
            searched.append(
                (
                    name,
                    len(s),
                    np.mean(s <= 30),
                    np.mean(s <= 45),
                    s.mean(),
                    s.max(),
                    np.mean(search_elevation_errors),
                    np.mean(search_seconds),
                )
            )
    print(
        f"pose {args.pose_checkpoint}"
        + (f", NOC {args.noc_checkpoint}" if args.noc_checkpoint else "")
        + f"; photos cropped to {args.resolution} px"
    )
    print(
        "| photos | n | azimuth bin acc | within 30 deg | within 45 deg | mean az error | mean el error | NOC error |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for name, n, acc, w30, w45, az, el, noc in rows:
        print(
            f"| {name} | {n} | {acc:.2f} | {w30:.2f} | {w45:.2f} | {az:.1f} | {el:.1f} | "
            + ("-" if np.isnan(noc) else f"{noc:.3f}")
            + " |"
        )
    if searched:
        print("\npose network + silhouette search (infer transfer --pose auto):")
        print(
            "| photos | n | within 30 deg | within 45 deg | mean az error | max az error | mean el error | s per "
            "photo |"
        )
        print("| --- | --- | --- | --- | --- | --- | --- | --- |")
        for name, n, w30, w45, az, worst, el, sec in searched:
            print(f"| {name} | {n} | {w30:.2f} | {w45:.2f} | {az:.1f} | {worst:.0f} | {el:.1f} | {sec:.2f} |")
    print("chance: azimuth bin accuracy 0.08, mean azimuth error 90 deg")


if __name__ == "__main__":
    main()
