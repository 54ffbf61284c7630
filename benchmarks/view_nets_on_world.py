"""How well the pose and NOC networks read the synthetic world's photos (they never train on them).

    python benchmarks/view_nets_on_world.py --world WORLD --pose-checkpoint P [--noc-checkpoint N]
                                            [--resolution 64] [--queries-only]

Every photo of the world with a known camera (``images/`` of the training shapes and ``queries/`` of
the held-out shapes; their poses are in ``index.json``) goes through exactly the path of
``infer transfer``: the crop around its mask (``load_photo``), then ``predict_pose`` and
``predict_noc``. Prints, per set and overall: the azimuth bin accuracy (the true angle's bin), the
share within 30 and 45 degrees, the mean azimuth and elevation errors, and for the queries (whose
ground-truth NOC maps are stored) the mean NOC error over object pixels, in NOC units (the object's
box has diagonal 1). The figure to compare against is chance: 1/12 of azimuth bins, a mean error of
90 degrees.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from infer.transfer import TransferConfig, load_photo, predict_noc, predict_pose  # noqa: E402
from mesh2tex.io.images import load_image, load_mask  # noqa: E402
from mesh2tex.nn.pose import PoseBins  # noqa: E402
from mesh2tex.render import crop_square, object_box  # noqa: E402


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--world", required=True, help="a world from 'mesh2tex prepare synthetic'")
    parser.add_argument("--pose-checkpoint", required=True)
    parser.add_argument("--noc-checkpoint")
    parser.add_argument("--resolution", type=int, default=64, help="side of the photo crop (as infer transfer --resolution)")
    parser.add_argument("--queries-only", action="store_true", help="only the held-out query photos")
    args = parser.parse_args()

    world = Path(args.world)
    index = json.loads((world / "index.json").read_text())
    cfg = TransferConfig(resolution=args.resolution)
    device = torch.device("cpu")
    sets = {"queries (held-out shapes)": index["queries"]}
    if not args.queries_only:
        sets = {"photos (training shapes)": index["images"], **sets}
    bins = PoseBins()
    rows = []
    for name, entries in sets.items():
        errors, elevation_errors, hits, noc_errors = [], [], [], []
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
        e = np.array(errors)
        rows.append((name, len(entries), np.mean(hits), np.mean(e <= 30), np.mean(e <= 45), e.mean(), np.mean(elevation_errors),
                     np.mean(noc_errors) if noc_errors else float("nan")))
    print(f"pose {args.pose_checkpoint}" + (f", NOC {args.noc_checkpoint}" if args.noc_checkpoint else "")
          + f"; photos cropped to {args.resolution} px")
    print("| photos | n | azimuth bin acc | within 30 deg | within 45 deg | mean az error | mean el error | NOC error |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for name, n, acc, w30, w45, az, el, noc in rows:
        print(f"| {name} | {n} | {acc:.2f} | {w30:.2f} | {w45:.2f} | {az:.1f} | {el:.1f} | "
              + ("-" if np.isnan(noc) else f"{noc:.3f}") + " |")
    print("chance: azimuth bin accuracy 0.08, mean azimuth error 90 deg")


if __name__ == "__main__":
    main()
